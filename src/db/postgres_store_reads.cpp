// The reads of the PostgreSQL store (internal/postgres_store.h). Each read is one statement in
// a read-only transaction on a pooled connection: one committed snapshot, never half a commit.
#include <fmt/format.h>
#include <pqxx/pqxx>

#include "internal/postgres_store.h"
#include "internal/texture_codec.h"
#include "tessera/core/error.h"

namespace tessera::db::internal {

namespace {

// A bytea column's bytes (empty for NULL).
pqxx::binarystring blob(const pqxx::field& field) {
  return field.is_null() ? pqxx::binarystring(std::string()) : pqxx::binarystring(field);
}

TextureRecord recordOf(const pqxx::row& row, std::int64_t id) {
  TextureRecord r;
  r.id = id;
  r.kind = parseKind(row[0].c_str());
  r.texel_m = row[3].as<double>();
  const pqxx::binarystring png = blob(row[4]);
  decodePng(png.data(), png.size(), r.rgb, r.mask);
  if (r.rgb.cols != row[1].as<int>() || r.rgb.rows != row[2].as<int>()) {
    throw core::Error("PNG size differs from the stored width and height");
  }
  const pqxx::binarystring ccv = blob(row[5]), keypoints = blob(row[7]), descriptors = blob(row[8]);
  r.ccv = decodeFloats(ccv.data(), ccv.size());
  r.feature_kind = row[6].c_str();
  r.keypoints = decodeKeypoints(keypoints.data(), keypoints.size());
  r.descriptors = decodeDescriptors(descriptors.data(), descriptors.size());
  if (!row[9].is_null()) {
    r.lattice = Lattice{{row[9].as<double>(), row[10].as<double>()},
                        {row[11].as<double>(), row[12].as<double>()}};
  }
  r.content_key = row[13].c_str();
  r.run_id = row[14].is_null() ? 0 : row[14].as<std::int64_t>();
  r.source_patch = row[15].as<int>();
  r.name = row[16].c_str();
  return r;
}

}  // namespace

std::optional<std::int64_t> PostgresStore::findByContentKey(const std::string& key) const {
  return read([&](pqxx::read_transaction& tx) -> std::optional<std::int64_t> {
    const pqxx::result rows = tx.exec_params("SELECT id FROM textures WHERE content_key = $1", key);
    if (rows.empty()) return std::nullopt;
    return rows[0][0].as<std::int64_t>();
  });
}

std::optional<TextureRecord> PostgresStore::texture(std::int64_t id) const {
  return read([&](pqxx::read_transaction& tx) -> std::optional<TextureRecord> {
    const pqxx::result rows = tx.exec_params(
        "SELECT kind, width, height, texel_m, png, ccv, feature_kind, keypoints, descriptors, "
        "lattice_v1x, lattice_v1y, lattice_v2x, lattice_v2y, content_key, run_id, source_patch, "
        "name FROM textures WHERE id = $1",
        id);
    if (rows.empty()) return std::nullopt;
    try {
      return recordOf(rows[0], id);
    } catch (const core::Error& e) {
      throw core::Error(fmt::format("{}: texture {} is damaged: {}", location_, id, e.what()));
    }
  });
}

std::vector<CcvEntry> PostgresStore::ccvVectors(std::int64_t after_id) const {
  return read([&](pqxx::read_transaction& tx) {
    std::vector<CcvEntry> entries;
    for (const pqxx::row& row :
         tx.exec_params("SELECT id, ccv FROM textures WHERE id > $1 ORDER BY id", after_id)) {
      CcvEntry& entry = entries.emplace_back();
      entry.id = row[0].as<std::int64_t>();
      const pqxx::binarystring ccv = blob(row[1]);
      try {
        entry.ccv = decodeFloats(ccv.data(), ccv.size());
      } catch (const core::Error& e) {
        throw core::Error(
            fmt::format("{}: texture {} is damaged: {}", location_, entry.id, e.what()));
      }
    }
    return entries;
  });
}

std::vector<TextureSummary> PostgresStore::textures() const {
  return read([&](pqxx::read_transaction& tx) {
    std::vector<TextureSummary> summaries;
    for (const pqxx::row& row : tx.exec(
             "SELECT t.id, t.kind, t.width, t.height, t.run_id, t.source_patch, t.name, "
             "octet_length(t.png), (SELECT count(*) FROM instances i WHERE i.texture_id = t.id) "
             "FROM textures t ORDER BY t.id")) {
      TextureSummary& s = summaries.emplace_back();
      s.id = row[0].as<std::int64_t>();
      s.kind = parseKind(row[1].c_str());
      s.width = row[2].as<int>();
      s.height = row[3].as<int>();
      s.run_id = row[4].is_null() ? 0 : row[4].as<std::int64_t>();
      s.source_patch = row[5].as<int>();
      s.name = row[6].c_str();
      s.png_bytes = row[7].as<std::size_t>();
      s.uses = row[8].as<std::size_t>();
    }
    return summaries;
  });
}

std::vector<TextureInstance> PostgresStore::instances(std::optional<std::int64_t> run_id) const {
  return read([&](pqxx::read_transaction& tx) {
    const std::string columns =
        schema_version_ >= 2 ? "run_id, patch_id, version, layer, texture_id, a, b, tx, ty, "
                               "psnr_db, reused"
                             : "run_id, patch_id, version, 0, texture_id, a, b, tx, ty, "
                               "psnr_db, reused";
    const std::string order = schema_version_ >= 2 ? "run_id, patch_id, layer" : "run_id, patch_id";
    const pqxx::result rows =
        run_id ? tx.exec_params("SELECT " + columns + " FROM instances WHERE run_id = $1 ORDER BY " +
                                    order,
                                *run_id)
               : tx.exec("SELECT " + columns + " FROM instances ORDER BY " + order);
    std::vector<TextureInstance> instances;
    for (const pqxx::row& row : rows) {
      TextureInstance& i = instances.emplace_back();
      i.run_id = row[0].as<std::int64_t>();
      i.patch_id = row[1].as<int>();
      i.version = row[2].as<int>();
      i.layer = row[3].as<int>();
      i.texture_id = row[4].as<std::int64_t>();
      i.transform = {row[5].as<double>(), row[6].as<double>(), row[7].as<double>(),
                     row[8].as<double>()};
      if (!row[9].is_null()) i.psnr_db = row[9].as<double>();
      i.reused = row[10].as<int>() != 0;
    }
    return instances;
  });
}

std::vector<RunRecord> PostgresStore::runs() const {
  return read([&](pqxx::read_transaction& tx) {
    std::vector<RunRecord> runs;
    for (const pqxx::row& row :
         tx.exec("SELECT id, started_utc, source, finished FROM runs ORDER BY id")) {
      runs.push_back(
          {row[0].as<std::int64_t>(), row[1].c_str(), row[2].c_str(), row[3].as<int>() != 0});
    }
    return runs;
  });
}

StoreStats PostgresStore::stats() const {
  return read([&](pqxx::read_transaction& tx) {
    // One statement: every count from the same snapshot. The database's size on disk stands
    // for the SQLite file's.
    const pqxx::row row = tx.exec1(
        "SELECT (SELECT value FROM meta WHERE key = 'schema_version'), "
        "(SELECT count(*) FROM textures), (SELECT count(*) FROM textures WHERE kind = 'pattern'), "
        "(SELECT count(*) FROM instances), (SELECT count(*) FROM runs), "
        "(SELECT coalesce(sum(width::bigint * height), 0) FROM textures), "
        "pg_database_size(current_database())");
    StoreStats stats;
    stats.schema_version = std::stoi(row[0].c_str());
    stats.textures = row[1].as<std::size_t>();
    stats.patterns = row[2].as<std::size_t>();
    stats.instances = row[3].as<std::size_t>();
    stats.runs = row[4].as<std::size_t>();
    stats.texture_pixels = row[5].as<std::size_t>();
    stats.file_bytes = row[6].as<std::size_t>();
    return stats;
  });
}

}  // namespace tessera::db::internal
