// Opening, the reader pool and the writes of the SQLite store (internal/sqlite_store.h).
#include "internal/sqlite_store.h"

#include <algorithm>
#include <utility>

#include <fmt/format.h>

#include "internal/encoded_texture.h"
#include "internal/postgres_open.h"
#include "internal/schema_sql.h"
#include "internal/sqlite_schema.h"
#include "internal/sqlite_texture_rows.h"
#include "internal/texture_codec.h"
#include "tessera/core/error.h"

namespace tessera::db {
namespace internal {

namespace {

// The version of a (run, patch) that is stored: every layer has it (NULL when none is stored).
constexpr const char* kStoredVersion =
    "SELECT max(version) FROM instances WHERE run_id = ? AND patch_id = ?";

// Every layer of an older version goes when a newer version of the patch arrives, also the
// layers the newer version no longer has.
constexpr const char* kDeleteOlderVersions =
    "DELETE FROM instances WHERE run_id = ? AND patch_id = ? AND version < ?";

// After kDeleteOlderVersions only rows of the same version can conflict: the layer is replaced.
constexpr const char* kUpsertInstance =
    "INSERT INTO instances (run_id, patch_id, version, layer, texture_id, a, b, tx, ty, psnr_db, "
    "reused) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?) ON CONFLICT (run_id, patch_id, layer) DO "
    "UPDATE SET version = excluded.version, texture_id = excluded.texture_id, a = excluded.a, "
    "b = excluded.b, tx = excluded.tx, ty = excluded.ty, psnr_db = excluded.psnr_db, "
    "reused = excluded.reused";

bool rowExists(Statement& query, std::int64_t id) {
  query.reset();
  query.bind(1, id);
  return query.step();
}

}  // namespace

SqliteStore::SqliteStore(const std::filesystem::path& path, const OpenOptions& options)
    : path_(path), location_(path.string()) {
  if (sqlite3_threadsafe() == 0) {
    throw core::Error(location_ + ": this SQLite library was built without thread support");
  }
  const FileState state = inspectFile(path_);
  if (state != FileState::kDatabase) {
    const bool missing = state == FileState::kMissing;
    if (options.read_only || !options.create) {
      throw core::Error(fmt::format(
          "{}: {}", location_,
          missing ? "no such texture database" : "an empty file, not a texture database"));
    }
    const std::filesystem::path folder = path_.parent_path();
    if (!folder.empty() && !std::filesystem::is_directory(folder)) {
      throw core::Error(
          fmt::format("{}: cannot create the database: no folder {}", location_, folder.string()));
    }
    writer_ = std::make_unique<Connection>(path_, SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE);
    configureWriter(*writer_);
    schema_version_ = createSchema(*writer_);
    if (schema_version_ < kSchemaVersion) schema_version_ = migrateSchema(*writer_);
    return;
  }
  // Checked through a read-only connection first: a file this build must refuse (a newer
  // schema, another application's) is never written to, not even to switch it to WAL.
  auto checker = std::make_unique<Connection>(path_, SQLITE_OPEN_READONLY);
  configureReader(*checker);
  schema_version_ = checkSchema(*checker);
  if (!options.read_only) {
    writer_ = std::make_unique<Connection>(path_, SQLITE_OPEN_READWRITE);
    if (sqlite3_db_readonly(writer_->handle(), "main") == 1) {
      throw core::Error(location_ +
                        ": cannot write to it (read-only file or folder); open it "
                        "read-only to read it");
    }
    if (schema_version_ < kSchemaVersion) {
      // Before the switch to WAL: a migration that fails leaves the file exactly as it was.
      configureReader(*writer_);
      schema_version_ = migrateSchema(*writer_);
    }
    configureWriter(*writer_);
  }
  pool_.give(std::move(checker));
}

SqliteStore::~SqliteStore() {
  // Readers first: the last connection to close checkpoints the WAL into the main file and
  // removes it, which only the writer can do.
  pool_.clear();
  if (writer_) {
    // Back to a rollback journal as the writer leaves: the file then stands alone, and a
    // read-only open (db list, db show) creates no -wal and -shm beside it, as it would for a
    // WAL database. The read first makes the writer open the WAL itself, without which leaving
    // WAL mode leaves the -wal and -shm its readers opened. While another process has the
    // database open this fails at once (it needs an exclusive lock) and the file stays in WAL.
    sqlite3_busy_timeout(writer_->handle(), 0);
    sqlite3_exec(writer_->handle(),
                 "SELECT count(*) FROM sqlite_master; PRAGMA journal_mode = DELETE", nullptr,
                 nullptr, nullptr);
  }
  writer_.reset();
}

SqliteStore::ReadLease::ReadLease(const SqliteStore& store) : lease_(store.pool_) {
  if (lease_.connection()) return;
  // Opened outside the pool's lock: opening reads the file, and other readers need not wait
  // for it. Lent only once configured.
  auto connection = std::make_unique<Connection>(store.path_, SQLITE_OPEN_READONLY);
  configureReader(*connection);
  lease_.connection() = std::move(connection);
}

SqliteStore::ReadLease::~ReadLease() {
  lease_.connection()->rollbackQuietly();  // ends a read transaction an exception left open
}

Connection& SqliteStore::writer() {
  if (!writer_) throw core::Error(location_ + ": opened read-only; cannot write");
  return *writer_;
}

std::int64_t SqliteStore::beginRun(const std::string& source) {
  const std::lock_guard lock(write_mutex_);
  Connection& db = writer();
  Statement insert(db,
                   "INSERT INTO runs (started_utc, source, finished) VALUES "
                   "(strftime('%Y-%m-%dT%H:%M:%SZ', 'now'), ?, 0)");
  insert.bind(1, source).run();
  return db.lastInsertId();
}

void SqliteStore::finishRun(std::int64_t run_id) {
  const std::lock_guard lock(write_mutex_);
  Connection& db = writer();
  Statement update(db, "UPDATE runs SET finished = 1 WHERE id = ?");
  update.bind(1, run_id).run();
  if (db.changes() == 0) throw core::Error(fmt::format("{}: no run {}", location_, run_id));
}

std::vector<std::int64_t> SqliteStore::commit(const Commit& commit) {
  std::vector<EncodedTexture> encoded;
  encoded.reserve(commit.textures.size());
  for (std::size_t i = 0; i < commit.textures.size(); ++i) {
    encoded.push_back(encodeTexture(commit.textures[i], location_, i));
  }
  const std::lock_guard lock(write_mutex_);
  Connection& db = writer();
  // IMMEDIATE takes the write lock up front, so another process cannot make the transaction
  // fail half-way with SQLITE_BUSY.
  db.exec("BEGIN IMMEDIATE");
  try {
    std::vector<std::int64_t> ids = writeCommit(commit, encoded);
    db.exec("COMMIT");
    return ids;
  } catch (const std::exception& e) {
    db.rollbackQuietly();
    throw core::Error(
        fmt::format("{} (the commit was rolled back; nothing of it is stored)", e.what()));
  }
}

std::vector<std::int64_t> SqliteStore::removeUnused(std::int64_t run_id,
                                                    const std::vector<std::int64_t>& candidates) {
  std::vector<std::int64_t> removed;
  if (candidates.empty()) return removed;
  const std::lock_guard lock(write_mutex_);
  Connection& db = writer();
  db.exec("BEGIN IMMEDIATE");
  try {
    const std::string sql = removeUnusedTextureSql(SqlDialect::kSqlite);
    Statement remove(db, sql.c_str());
    for (const std::int64_t id : candidates) {
      remove.reset();
      remove.bind(1, id).bind(2, run_id).run();
      if (db.changes() > 0) removed.push_back(id);
    }
    db.exec("COMMIT");
  } catch (const std::exception& e) {
    db.rollbackQuietly();
    throw core::Error(fmt::format("{}: cannot remove unused textures (nothing removed): {}",
                                  location_, e.what()));
  }
  std::sort(removed.begin(), removed.end());
  removed.erase(std::unique(removed.begin(), removed.end()), removed.end());
  return removed;
}

std::vector<std::int64_t> SqliteStore::writeCommit(const Commit& commit,
                                                   const std::vector<EncodedTexture>& encoded) {
  Connection& db = *writer_;
  Statement find(db, "SELECT id FROM textures WHERE content_key = ?");
  Statement insert(db, kInsertTexture);
  std::vector<std::int64_t> ids;
  ids.reserve(encoded.size());
  for (const EncodedTexture& texture : encoded) {
    // The same pixels are stored once: an existing texture (from any commit, or earlier in
    // this one) is reused. The UNIQUE content_key makes a duplicate impossible regardless.
    find.reset();
    find.bind(1, texture.content_key);
    ids.push_back(find.step() ? find.int64(0) : insertTexture(insert, db, texture));
  }

  Statement retire(db, "DELETE FROM instances WHERE run_id = ? AND patch_id = ?");
  for (const RetiredPatch& gone : commit.retired) {
    retire.reset();
    retire.bind(1, gone.run_id).bind(2, std::int64_t{gone.patch_id}).run();
  }

  Statement texture_exists(db, "SELECT 1 FROM textures WHERE id = ?");
  Statement run_exists(db, "SELECT 1 FROM runs WHERE id = ?");
  Statement stored_version(db, kStoredVersion);
  Statement delete_older(db, kDeleteOlderVersions);
  Statement upsert(db, kUpsertInstance);
  for (const TextureInstance& instance : commit.instances) {
    const std::string which = instanceName(instance);
    const std::int64_t texture_id = instanceTextureId(instance, ids, location_);
    if (instance.texture_id >= 0 && !rowExists(texture_exists, texture_id)) {
      // The foreign key would refuse it too, but without saying which.
      throw core::Error(
          fmt::format("{}: the instance of {} refers to texture {}, which "
                      "is not stored",
                      location_, which, texture_id));
    }
    if (!rowExists(run_exists, instance.run_id)) {
      throw core::Error(
          fmt::format("{}: the instance of {} belongs to run {}, which is "
                      "not stored (call beginRun first)",
                      location_, which, instance.run_id));
    }
    const auto patch_id = std::int64_t{instance.patch_id};
    const auto version = std::int64_t{instance.version};
    stored_version.reset();
    stored_version.bind(1, instance.run_id).bind(2, patch_id);
    const bool newer_stored =
        stored_version.step() && !stored_version.isNull(0) && stored_version.int64(0) > version;
    stored_version.reset();
    if (newer_stored) continue;  // an older version arriving late: none of its layers is stored
    delete_older.reset();
    delete_older.bind(1, instance.run_id).bind(2, patch_id).bind(3, version).run();
    const core::Similarity2& t = instance.transform;
    upsert.reset();
    upsert.bind(1, instance.run_id)
        .bind(2, patch_id)
        .bind(3, version)
        .bind(4, std::int64_t{instance.layer})
        .bind(5, texture_id)
        .bind(6, t.a)
        .bind(7, t.b)
        .bind(8, t.tx)
        .bind(9, t.ty);
    if (instance.psnr_db) upsert.bind(10, *instance.psnr_db);
    upsert.bind(11, std::int64_t{instance.reused ? 1 : 0}).run();
  }
  return ids;
}

}  // namespace internal

std::unique_ptr<TextureStore> openSqliteStore(const std::filesystem::path& path,
                                              const OpenOptions& options) {
  return std::make_unique<internal::SqliteStore>(path, options);
}

std::unique_ptr<TextureStore> openTextureStore(const std::string& location,
                                               const OpenOptions& options) {
  if (internal::isPostgresUrl(location)) return internal::openPostgresStore(location, options);
  return openSqliteStore(location, options);
}

std::string lastingLocation(const std::string& location) {
  if (internal::isPostgresUrl(location)) return internal::redactedUrl(location);
  std::error_code ec;
  const std::filesystem::path absolute = std::filesystem::absolute(location, ec);
  return ec ? location : absolute.lexically_normal().string();
}

}  // namespace tessera::db
