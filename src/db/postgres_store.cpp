// Opening, the connection pool and the writes of the PostgreSQL store
// (internal/postgres_store.h).
#include "internal/postgres_store.h"

#include <algorithm>
#include <utility>

#include <fmt/format.h>
#include <spdlog/spdlog.h>
#include <pqxx/pqxx>

#include "internal/encoded_texture.h"
#include "internal/schema_sql.h"
#include "tessera/core/error.h"

namespace tessera::db::internal {

namespace {

// The key of the advisory lock that serialises schema creation and migration between
// processes ("TESS", as the SQLite files' application_id).
constexpr std::int64_t kSchemaLockKey = 0x54455353;

// One round trip per texture (on a busy robot each one waits for the server process to be
// scheduled): its id if the same pixels are stored, else inserted. Looked up first, because
// a conflicting INSERT would use up a sequence number for nothing; ON CONFLICT covers another
// process inserting the same pixels meanwhile (then no row comes back, and a look-up follows).
constexpr const char* kStoreTexture =
    "WITH found AS (SELECT id FROM textures WHERE content_key = $14), inserted AS ("
    "INSERT INTO textures (kind, width, height, texel_m, png, ccv, feature_kind, keypoints, "
    "descriptors, lattice_v1x, lattice_v1y, lattice_v2x, lattice_v2y, content_key, run_id, "
    "source_patch, name) SELECT $1::text, $2::integer, $3::integer, $4::double precision, "
    "$5::bytea, $6::bytea, $7::text, $8::bytea, $9::bytea, $10::double precision, "
    "$11::double precision, $12::double precision, $13::double precision, $14::text, "
    "$15::bigint, $16::integer, $17::text WHERE NOT EXISTS (SELECT 1 FROM found) "
    "ON CONFLICT (content_key) DO NOTHING RETURNING id) "
    "SELECT id FROM found UNION ALL SELECT id FROM inserted";

// One round trip per instance, with the SQLite store's rules: nothing when a newer version of
// the patch is stored; else the older versions' other layers go, and this layer is inserted
// or replaces the same layer of an older or the same version.
constexpr const char* kPutInstance =
    "WITH newer AS (SELECT 1 FROM instances WHERE run_id = $1 AND patch_id = $2 AND version > $3), "
    "gone AS (DELETE FROM instances WHERE run_id = $1 AND patch_id = $2 AND version < $3 AND "
    "layer <> $4) "
    "INSERT INTO instances (run_id, patch_id, version, layer, texture_id, a, b, tx, ty, psnr_db, "
    "reused) SELECT $1::bigint, $2::integer, $3::integer, $4::integer, $5::bigint, "
    "$6::double precision, $7::double precision, $8::double precision, $9::double precision, "
    "$10::double precision, $11::integer WHERE NOT EXISTS (SELECT 1 FROM newer) "
    "ON CONFLICT (run_id, patch_id, layer) DO UPDATE SET version = excluded.version, "
    "texture_id = excluded.texture_id, a = excluded.a, b = excluded.b, tx = excluded.tx, "
    "ty = excluded.ty, psnr_db = excluded.psnr_db, reused = excluded.reused "
    "WHERE instances.version <= excluded.version";

pqxx::binarystring bytes(const Bytes& b) { return pqxx::binarystring(b.data(), b.size()); }

// A nullable double as a statement parameter: libpqxx 6 takes nullptr for NULL.
template <typename F>
auto withOptional(const std::optional<double>& value, F&& call) {
  return value ? call(*value) : call(nullptr);
}

// The texture's id: inserted now, or already stored by any process (the same pixels).
std::int64_t storeTexture(pqxx::work& tx, const EncodedTexture& e) {
  const TextureRecord& r = *e.record;
  const auto insert = [&](auto v1x, auto v1y, auto v2x, auto v2y, auto run_id) {
    return tx.exec_params(kStoreTexture, std::string(kindName(r.kind)), r.rgb.cols, r.rgb.rows,
                          r.texel_m, bytes(e.png), bytes(e.ccv), r.feature_kind,
                          bytes(e.keypoints), bytes(e.descriptors), v1x, v1y, v2x, v2y,
                          e.content_key, run_id, r.source_patch, r.name);
  };
  const auto insertRun = [&](auto v1x, auto v1y, auto v2x, auto v2y) {
    return r.run_id != 0 ? insert(v1x, v1y, v2x, v2y, r.run_id)
                         : insert(v1x, v1y, v2x, v2y, nullptr);
  };
  const pqxx::result inserted =
      r.lattice ? insertRun(r.lattice->v1.x(), r.lattice->v1.y(), r.lattice->v2.x(),
                            r.lattice->v2.y())
                : insertRun(nullptr, nullptr, nullptr, nullptr);
  if (!inserted.empty()) return inserted[0][0].as<std::int64_t>();
  // Another process stored the same pixels meanwhile: ON CONFLICT waited for it to commit,
  // and this statement sees it.
  return tx.exec_params1("SELECT id FROM textures WHERE content_key = $1", e.content_key)[0]
      .as<std::int64_t>();
}

int readSchemaVersion(pqxx::work& tx, const std::string& location) {
  const pqxx::result rows = tx.exec(
      "SELECT (SELECT value FROM meta WHERE key = 'application'), "
      "(SELECT value FROM meta WHERE key = 'schema_version')");
  const std::string application = rows[0][0].is_null() ? "" : rows[0][0].c_str();
  if (application != "tessera") {
    throw core::Error(fmt::format(
        "{}: has a meta table, but not a tessera texture database's (application '{}')",
        location, application));
  }
  const std::string text = rows[0][1].is_null() ? "" : rows[0][1].c_str();
  int version = 0;
  try {
    version = std::stoi(text);
  } catch (const std::exception&) {
    throw core::Error(fmt::format("{}: unreadable schema_version '{}' in the meta table",
                                  location, text));
  }
  if (version > kSchemaVersion) {
    throw core::Error(fmt::format(
        "{}: written by a newer tessera (schema {}; this build reads up to {}); upgrade tessera "
        "to use it",
        location, version, kSchemaVersion));
  }
  if (version < 1) throw core::Error(fmt::format("{}: bad schema_version {}", location, version));
  return version;
}

void createSchema(pqxx::work& tx) {
  tx.exec(coreTablesSql(SqlDialect::kPostgres));
  // PNG is compressed already: TOAST's own compression would only cost time.
  tx.exec("ALTER TABLE textures ALTER COLUMN png SET STORAGE EXTERNAL");
  tx.exec(instancesTableSql(SqlDialect::kPostgres, "instances") + instancesIndexSql());
  tx.exec_params(
      "INSERT INTO meta (key, value) VALUES ('schema_version', $1), ('application', 'tessera'), "
      "('created_utc', to_char(now() AT TIME ZONE 'UTC', 'YYYY-MM-DD\"T\"HH24:MI:SS\"Z\"'))",
      std::to_string(kSchemaVersion));
}

// Schema 1 -> 2, as the SQLite store migrates: instances get a layer (0 for every row) and
// UNIQUE (run_id, patch_id, layer).
void migrateSchema(pqxx::work& tx) {
  static_assert(kSchemaVersion == 2, "add the migration to the new schema version here");
  tx.exec(instancesTableSql(SqlDialect::kPostgres, "instances_v2") +
          "INSERT INTO instances_v2 (run_id, patch_id, version, layer, texture_id, a, b, tx, ty, "
          "psnr_db, reused) SELECT run_id, patch_id, version, 0, texture_id, a, b, tx, ty, "
          "psnr_db, reused FROM instances; DROP TABLE instances; "
          "ALTER TABLE instances_v2 RENAME TO instances; " +
          instancesIndexSql());
  tx.exec_params("UPDATE meta SET value = $1 WHERE key = 'schema_version'",
                 std::to_string(kSchemaVersion));
}

// libpq waits for ever by default; a robot's commits must not: 5 s to connect, 10 s for data
// the server does not acknowledge (a network that vanished), unless the URL says otherwise.
std::string withTimeouts(const std::string& url) {
  std::string out = url;
  for (const char* setting : {"connect_timeout=5", "tcp_user_timeout=10000"}) {
    const std::string key = std::string(setting).substr(0, std::string(setting).find('=') + 1);
    if (out.find(key) != std::string::npos) continue;
    out += out.find('?') == std::string::npos ? '?' : '&';
    out += setting;
  }
  return out;
}

}  // namespace

std::string redactedUrl(const std::string& url) {
  // (No std::regex: GCC 12 at -O1 warns inside it, and warnings are errors in CI.)
  std::string out = url;
  // user:password@ -> user@, in the authority after the scheme.
  const std::size_t scheme = out.find("://");
  if (scheme != std::string::npos) {
    const std::size_t start = scheme + 3;
    const std::size_t end = out.find_first_of("/?", start);
    const std::size_t at = out.rfind('@', end == std::string::npos ? out.size() : end);
    if (at != std::string::npos && at > start) {
      const std::size_t colon = out.find(':', start);
      if (colon != std::string::npos && colon < at) out.erase(colon, at - colon);
    }
  }
  // A password=... parameter goes with its separator.
  for (std::size_t at = out.find("password="); at != std::string::npos;
       at = out.find("password=", at)) {
    if (at == 0 || (out[at - 1] != '?' && out[at - 1] != '&')) {
      at += 9;
      continue;
    }
    std::size_t end = out.find('&', at);
    end = end == std::string::npos ? out.size() : end + 1;
    out.erase(at, end - at);
  }
  while (!out.empty() && (out.back() == '&' || out.back() == '?')) out.pop_back();
  return out;
}

// libpq's messages span lines ("...failed: Connection refused\n\tIs the server running...");
// a log line should not.
std::string oneLine(const std::string& text) {
  std::string out;
  for (const char c : text) {
    if (c == '\n') {
      out += "; ";
    } else if (c != '\t') {
      out += c;
    }
  }
  while (!out.empty() && (out.back() == ' ' || out.back() == ';')) out.pop_back();
  return out;
}

bool isPostgresUrl(const std::string& location) {
  return location.rfind("postgresql://", 0) == 0 || location.rfind("postgres://", 0) == 0;
}

std::unique_ptr<TextureStore> openPostgresStore(const std::string& url,
                                                const OpenOptions& options) {
  auto server = std::make_unique<PostgresStore>(url, options);
  if (options.read_only) return server;
  return queueWhileAway(std::move(server), options);
}

std::unique_ptr<pqxx::connection> PostgresStore::connect() const {
  try {
    return std::make_unique<pqxx::connection>(url_);
  } catch (const std::exception& e) {
    // libpq's reasons (refused, unknown host, authentication failed) name no password.
    throw ServerUnavailable(fmt::format("{}: cannot connect: {}", location_, oneLine(e.what())));
  }
}

PostgresStore::PostgresStore(const std::string& url, const OpenOptions& options)
    : url_(withTimeouts(url)), location_(redactedUrl(url)) {
  std::unique_ptr<pqxx::connection> first = connect();
  try {
    pqxx::work tx(*first);
    // Serialises creation and migration between processes opening the database at once.
    tx.exec_params("SELECT pg_advisory_xact_lock($1)", kSchemaLockKey);
    const pqxx::row tables = tx.exec1(
        "SELECT to_regclass('meta') IS NOT NULL, to_regclass('textures') IS NOT NULL");
    if (!tables[0].as<bool>()) {
      if (tables[1].as<bool>()) {
        throw core::Error(location_ + ": has a textures table but no meta table: not a tessera "
                                      "texture database");
      }
      if (options.read_only || !options.create) {
        throw core::Error(location_ + ": no tessera texture database there (no meta table)");
      }
      createSchema(tx);
      schema_version_ = kSchemaVersion;
    } else {
      schema_version_ = readSchemaVersion(tx, location_);
      if (schema_version_ < kSchemaVersion && !options.read_only) {
        migrateSchema(tx);
        schema_version_ = kSchemaVersion;
      }
    }
    tx.commit();
  } catch (const core::Error&) {
    throw;
  } catch (const pqxx::insufficient_privilege& e) {
    throw core::Error(fmt::format("{}: not allowed to create or migrate the schema ({}); ask the "
                                  "database's owner (docs/FLEET.md)",
                                  location_, e.what()));
  } catch (const std::exception& e) {
    throw core::Error(fmt::format("{}: cannot open the texture database: {}", location_, e.what()));
  }
  read_only_ = options.read_only;
  pool_.give(std::move(first));
}

PostgresStore::~PostgresStore() = default;

bool connectionLost(const std::exception& error) {
  if (dynamic_cast<const pqxx::broken_connection*>(&error) ||
      dynamic_cast<const pqxx::in_doubt_error*>(&error)) {
    return true;
  }
  if (const auto* sql = dynamic_cast<const pqxx::sql_error*>(&error)) {
    const std::string& state = sql->sqlstate();
    return state.rfind("08", 0) == 0 || state.rfind("57P", 0) == 0;
  }
  return false;
}

void PostgresStore::checkWritable() const {
  if (read_only_) throw core::Error(location_ + ": opened read-only; cannot write");
}

std::int64_t PostgresStore::beginRun(const std::string& source) {
  checkWritable();
  const std::lock_guard lock(write_mutex_);
  try {
    return onConnection(writer_, [&](pqxx::connection& db) {
      pqxx::work tx(db);
      const std::int64_t id =
          tx.exec_params1(
                "INSERT INTO runs (started_utc, source, finished) VALUES (to_char(now() AT "
                "TIME ZONE 'UTC', 'YYYY-MM-DD\"T\"HH24:MI:SS\"Z\"'), $1, 0) RETURNING id",
                source)[0]
              .as<std::int64_t>();
      tx.commit();
      return id;
    });
  } catch (const core::Error&) {
    throw;
  } catch (const std::exception& e) {
    throw core::Error(fmt::format("{}: cannot begin a run: {}", location_, e.what()));
  }
}

void PostgresStore::finishRun(std::int64_t run_id) {
  checkWritable();
  const std::lock_guard lock(write_mutex_);
  std::size_t changed = 0;
  try {
    changed = onConnection(writer_, [&](pqxx::connection& db) {
      pqxx::work tx(db);
      const std::size_t rows =
          tx.exec_params("UPDATE runs SET finished = 1 WHERE id = $1", run_id).affected_rows();
      tx.commit();
      return rows;
    });
  } catch (const core::Error&) {
    throw;
  } catch (const std::exception& e) {
    throw core::Error(fmt::format("{}: cannot finish run {}: {}", location_, run_id, e.what()));
  }
  if (changed == 0) throw core::Error(fmt::format("{}: no run {}", location_, run_id));
}

std::vector<std::int64_t> PostgresStore::commit(const Commit& commit) {
  checkWritable();
  std::vector<EncodedTexture> encoded;
  encoded.reserve(commit.textures.size());
  for (std::size_t i = 0; i < commit.textures.size(); ++i) {
    encoded.push_back(encodeTexture(commit.textures[i], location_, i));
  }
  const std::lock_guard lock(write_mutex_);
  try {
    return onConnection(writer_, [&](pqxx::connection& db) {
      return writeCommit(db, commit, encoded);
    });
  } catch (const ServerUnavailable&) {
    throw;  // the caller may queue it and try again
  } catch (const std::exception& e) {
    throw core::Error(
        fmt::format("{} (the commit was rolled back; nothing of it is stored)", e.what()));
  }
}

std::vector<std::int64_t> PostgresStore::removeUnused(std::int64_t run_id,
                                                      const std::vector<std::int64_t>& candidates) {
  checkWritable();
  std::vector<std::int64_t> removed;
  const std::lock_guard lock(write_mutex_);
  if (candidates.empty() || !may_remove_) return removed;
  try {
    // Another process committing an instance of a candidate at the same time: the foreign key
    // refuses whichever of the two comes second (that instance, or this removal, which then
    // removes nothing). Never an instance of a removed texture.
    onConnection(writer_, [&](pqxx::connection& db) {
      removed.clear();
      pqxx::work tx(db);
      const std::string sql = removeUnusedTextureSql(SqlDialect::kPostgres);
      for (const std::int64_t id : candidates) {
        if (tx.exec_params(sql, id, run_id).affected_rows() > 0) removed.push_back(id);
      }
      tx.commit();
      return 0;
    });
  } catch (const ServerUnavailable&) {
    throw;
  } catch (const pqxx::insufficient_privilege&) {
    // A robot's role may not delete textures (docs/FLEET.md): they stay for the owner's prune.
    may_remove_ = false;
    spdlog::info(
        "{}: this role may not delete textures; the ones older patch versions no "
        "longer use stay until the database's owner runs `tessera db prune`",
        location_);
    return {};
  } catch (const std::exception& e) {
    throw core::Error(fmt::format("{}: cannot remove unused textures (nothing removed): {}",
                                  location_, e.what()));
  }
  std::sort(removed.begin(), removed.end());
  removed.erase(std::unique(removed.begin(), removed.end()), removed.end());
  return removed;
}

std::vector<std::int64_t> PostgresStore::writeCommit(pqxx::connection& db, const Commit& commit,
                                                     const std::vector<EncodedTexture>& encoded) {
  // READ COMMITTED: each statement sees what other processes committed before it, which is
  // what ON CONFLICT DO NOTHING and the look-up after it need. No two runs write the same
  // (run, patch), so instance rows never conflict between processes.
  pqxx::work tx(db);
  std::vector<std::int64_t> ids;
  ids.reserve(encoded.size());
  for (const EncodedTexture& texture : encoded) ids.push_back(storeTexture(tx, texture));

  for (const RetiredPatch& gone : commit.retired) {
    tx.exec_params("DELETE FROM instances WHERE run_id = $1 AND patch_id = $2", gone.run_id,
                   gone.patch_id);
  }
  for (const TextureInstance& instance : commit.instances) {
    const std::string which = instanceName(instance);
    const std::int64_t texture_id = instanceTextureId(instance, ids, location_);
    const core::Similarity2& t = instance.transform;
    try {
      withOptional(instance.psnr_db, [&](auto psnr) {
        return tx.exec_params(kPutInstance, instance.run_id, instance.patch_id, instance.version,
                              instance.layer, texture_id, t.a, t.b, t.tx, t.ty, psnr,
                              instance.reused ? 1 : 0);
      });
    } catch (const pqxx::foreign_key_violation& e) {
      // The constraint's name says which reference is missing.
      if (std::string(e.what()).find("texture_id") != std::string::npos) {
        throw core::Error(fmt::format(
            "{}: the instance of {} refers to texture {}, which is not stored", location_, which,
            texture_id));
      }
      throw core::Error(fmt::format(
          "{}: the instance of {} belongs to run {}, which is not stored (call beginRun first)",
          location_, which, instance.run_id));
    }
  }
  tx.commit();
  return ids;
}

}  // namespace tessera::db::internal
