// The reads of the SQLite store (internal/sqlite_store.h). Each read is one SQL statement on a
// pooled read-only connection, so it sees one committed snapshot: never half of a commit.
#include <fmt/format.h>

#include "internal/file_bytes.h"
#include "internal/sqlite_store.h"
#include "internal/sqlite_texture_rows.h"
#include "internal/texture_codec.h"
#include "tessera/core/error.h"

namespace tessera::db::internal {

std::optional<std::int64_t> SqliteStore::findByContentKey(const std::string& key) const {
  const ReadLease db(*this);
  Statement query(*db, "SELECT id FROM textures WHERE content_key = ?");
  query.bind(1, key);
  if (!query.step()) return std::nullopt;
  return query.int64(0);
}

std::optional<TextureRecord> SqliteStore::texture(std::int64_t id) const {
  const ReadLease db(*this);
  Statement query(*db, kSelectTexture);
  query.bind(1, id);
  if (!query.step()) return std::nullopt;
  try {
    return recordOf(query, id);
  } catch (const core::Error& e) {
    throw core::Error(fmt::format("{}: texture {} is damaged: {}", location_, id, e.what()));
  }
}

std::vector<CcvEntry> SqliteStore::ccvVectors(std::int64_t after_id) const {
  const ReadLease db(*this);
  Statement query(*db, "SELECT id, ccv FROM textures WHERE id > ? ORDER BY id");
  query.bind(1, after_id);
  std::vector<CcvEntry> entries;
  while (query.step()) {
    CcvEntry& entry = entries.emplace_back();
    entry.id = query.int64(0);
    try {
      entry.ccv = decodeFloats(query.blobData(1), query.blobSize(1));
    } catch (const core::Error& e) {
      throw core::Error(
          fmt::format("{}: texture {} is damaged: {}", location_, entry.id, e.what()));
    }
  }
  return entries;
}

std::vector<TextureSummary> SqliteStore::textures() const {
  const ReadLease db(*this);
  // length(png) reads the blob's size from the record header, not the blob itself.
  Statement query(*db,
                  "SELECT t.id, t.kind, t.width, t.height, t.run_id, t.source_patch, t.name, "
                  "length(t.png), (SELECT count(*) FROM instances i WHERE i.texture_id = t.id) "
                  "FROM textures t ORDER BY t.id");
  std::vector<TextureSummary> summaries;
  while (query.step()) {
    TextureSummary& s = summaries.emplace_back();
    s.id = query.int64(0);
    s.kind = query.text(1) == "pattern" ? TextureKind::kPattern : TextureKind::kSingle;
    s.width = static_cast<int>(query.int64(2));
    s.height = static_cast<int>(query.int64(3));
    s.run_id = query.int64(4);
    s.source_patch = static_cast<int>(query.int64(5));
    s.name = query.text(6);
    s.png_bytes = static_cast<std::size_t>(query.int64(7));
    s.uses = static_cast<std::size_t>(query.int64(8));
  }
  return summaries;
}

std::vector<TextureInstance> SqliteStore::instances(std::optional<std::int64_t> run_id) const {
  // Schema 1 (open read-only, so not migrated) has no layer column: each patch has only its
  // texture, layer 0.
  const char* sql =
      schema_version_ >= 2
          ? "SELECT run_id, patch_id, version, layer, texture_id, a, b, tx, ty, psnr_db, reused "
            "FROM instances WHERE ?1 IS NULL OR run_id = ?1 ORDER BY run_id, patch_id, layer"
          : "SELECT run_id, patch_id, version, 0, texture_id, a, b, tx, ty, psnr_db, reused "
            "FROM instances WHERE ?1 IS NULL OR run_id = ?1 ORDER BY run_id, patch_id";
  const ReadLease db(*this);
  Statement query(*db, sql);
  if (run_id) query.bind(1, *run_id);
  std::vector<TextureInstance> instances;
  while (query.step()) {
    TextureInstance& i = instances.emplace_back();
    i.run_id = query.int64(0);
    i.patch_id = static_cast<int>(query.int64(1));
    i.version = static_cast<int>(query.int64(2));
    i.layer = static_cast<int>(query.int64(3));
    i.texture_id = query.int64(4);
    i.transform = {query.real(5), query.real(6), query.real(7), query.real(8)};
    if (!query.isNull(9)) i.psnr_db = query.real(9);
    i.reused = query.int64(10) != 0;
  }
  return instances;
}

std::vector<RunRecord> SqliteStore::runs() const {
  const ReadLease db(*this);
  Statement query(*db, "SELECT id, started_utc, source, finished FROM runs ORDER BY id");
  std::vector<RunRecord> runs;
  while (query.step()) {
    runs.push_back({query.int64(0), query.text(1), query.text(2), query.int64(3) != 0});
  }
  return runs;
}

StoreStats SqliteStore::stats() const {
  StoreStats stats;
  {
    const ReadLease db(*this);
    // One statement, so that every count comes from the same snapshot.
    Statement query(*db,
                    "SELECT (SELECT value FROM meta WHERE key = 'schema_version'), "
                    "(SELECT count(*) FROM textures), "
                    "(SELECT count(*) FROM textures WHERE kind = 'pattern'), "
                    "(SELECT count(*) FROM instances), (SELECT count(*) FROM runs), "
                    "(SELECT coalesce(sum(width * height), 0) FROM textures)");
    query.step();
    stats.schema_version = static_cast<int>(query.int64(0));
    stats.textures = static_cast<std::size_t>(query.int64(1));
    stats.patterns = static_cast<std::size_t>(query.int64(2));
    stats.instances = static_cast<std::size_t>(query.int64(3));
    stats.runs = static_cast<std::size_t>(query.int64(4));
    stats.texture_pixels = static_cast<std::size_t>(query.int64(5));
  }
  // The -wal holds commits not yet checkpointed into the main file: part of the database.
  stats.file_bytes = fileBytes(path_) + fileBytes(path_.string() + "-wal");
  return stats;
}

}  // namespace tessera::db::internal
