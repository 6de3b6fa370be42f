#include "internal/sqlite_schema.h"

#include <array>
#include <cstring>
#include <fstream>
#include <string>

#include <fmt/format.h>

#include "internal/schema_sql.h"
#include "tessera/core/error.h"
#include "tessera/db/texture_store.h"

namespace tessera::db::internal {

namespace {

constexpr std::array<char, 16> kSqliteMagic = {'S', 'Q', 'L', 'i', 't', 'e', ' ', 'f',
                                               'o', 'r', 'm', 'a', 't', ' ', '3', '\0'};

std::int32_t bigEndian32(const unsigned char* bytes) {
  return static_cast<std::int32_t>((std::uint32_t{bytes[0]} << 24) |
                                   (std::uint32_t{bytes[1]} << 16) |
                                   (std::uint32_t{bytes[2]} << 8) | std::uint32_t{bytes[3]});
}

core::Error newerSchema(const std::string& path, std::int64_t version) {
  return core::Error(fmt::format(
      "{}: written by a newer tessera (schema {}; this build reads up to {}); upgrade tessera "
      "to use it",
      path, version, kSchemaVersion));
}

core::Error foreignDatabase(const std::string& path, std::int32_t application_id) {
  return core::Error(fmt::format(
      "{}: a SQLite database, but not a tessera texture database (application_id {:#x}, "
      "tessera's is {:#x})",
      path, static_cast<std::uint32_t>(application_id),
      static_cast<std::uint32_t>(kApplicationId)));
}

std::int64_t singleInt(Connection& connection, const char* sql) {
  Statement query(connection, sql);
  return query.step() ? query.int64(0) : 0;
}

int checkSchemaRows(Connection& connection) {
  const std::string& path = connection.path();
  // user_version mirrors the schema version in the file header; it is read first because a
  // newer schema may have changed the meta table itself.
  const std::int64_t header_version = singleInt(connection, "PRAGMA user_version");
  if (header_version > kSchemaVersion) throw newerSchema(path, header_version);
  const auto application_id =
      static_cast<std::int32_t>(singleInt(connection, "PRAGMA application_id"));
  if (application_id != kApplicationId) throw foreignDatabase(path, application_id);
  if (singleInt(connection,
                "SELECT count(*) FROM sqlite_master WHERE type = 'table' AND name = 'meta'") == 0) {
    throw core::Error(
        fmt::format("{}: a tessera database without its meta table (damaged?)", path));
  }
  Statement query(connection, "SELECT value FROM meta WHERE key = 'schema_version'");
  const std::string text = query.step() ? query.text(0) : "";
  std::int64_t version = 0;
  try {
    version = std::stoll(text);
  } catch (const std::exception&) {
    throw core::Error(
        fmt::format("{}: unreadable schema_version '{}' in the meta table", path, text));
  }
  if (version > kSchemaVersion) throw newerSchema(path, version);
  if (version < 1) throw core::Error(fmt::format("{}: bad schema_version {}", path, version));
  return static_cast<int>(version);
}

}  // namespace

FileState inspectFile(const std::filesystem::path& path) {
  namespace fs = std::filesystem;
  std::error_code ec;
  const fs::file_status status = fs::status(path, ec);
  if (status.type() == fs::file_type::not_found) return FileState::kMissing;
  if (ec) throw core::Error(fmt::format("{}: cannot read it: {}", path.string(), ec.message()));
  if (fs::is_directory(status)) {
    throw core::Error(fmt::format("{}: is a folder, not a texture database", path.string()));
  }
  const std::uintmax_t bytes = fs::file_size(path, ec);
  const fs::path wal = fs::path(path.string() + "-wal");
  const std::uintmax_t wal_bytes = fs::exists(wal, ec) ? fs::file_size(wal, ec) : 0;
  if (bytes == 0 && wal_bytes == 0) return FileState::kEmpty;
  if (bytes == 0) return FileState::kDatabase;  // all of it still in the -wal: SQLite decides

  std::array<unsigned char, 100> header{};
  std::ifstream in(path, std::ios::binary);
  if (!in) throw core::Error(fmt::format("{}: cannot read it", path.string()));
  in.read(reinterpret_cast<char*>(header.data()), header.size());
  if (in.gcount() != static_cast<std::streamsize>(header.size()) ||
      std::memcmp(header.data(), kSqliteMagic.data(), kSqliteMagic.size()) != 0) {
    throw core::Error(
        fmt::format("{}: not a tessera texture database (not a SQLite file)", path.string()));
  }
  // With committed pages still in the -wal (after a crash), the header may predate the schema:
  // then only SQL can tell, and checkSchema does.
  if (wal_bytes == 0) {
    const std::int32_t user_version = bigEndian32(&header[60]);
    if (user_version > kSchemaVersion) throw newerSchema(path.string(), user_version);
    const std::int32_t application_id = bigEndian32(&header[68]);
    if (application_id != kApplicationId) throw foreignDatabase(path.string(), application_id);
  }
  return FileState::kDatabase;
}

void configureReader(Connection& connection) {
  // Waits out WAL recovery and checkpoints by other connections instead of failing at once.
  sqlite3_busy_timeout(connection.handle(), 5000);
}

void configureWriter(Connection& connection) {
  configureReader(connection);
  {
    // WAL: readers keep reading their snapshot while a commit is written.
    Statement mode(connection, "PRAGMA journal_mode = WAL");
    if (!mode.step() || mode.text(0) != "wal") {
      throw core::Error(fmt::format(
          "{}: cannot use write-ahead logging here (a network or read-only file system?)",
          connection.path()));
    }
  }
  // FULL syncs the WAL on every commit: a commit that returned survives a power loss too, not
  // just a killed process (for which NORMAL would do).
  connection.exec("PRAGMA synchronous = FULL");
  connection.exec("PRAGMA foreign_keys = ON");
}

int checkSchema(Connection& connection) {
  try {
    return checkSchemaRows(connection);
  } catch (const core::Error&) {
    const int code = sqlite3_errcode(connection.handle()) & 0xff;
    if (code == SQLITE_CORRUPT || code == SQLITE_NOTADB) {
      throw core::Error(fmt::format("{}: the database is corrupt ({})", connection.path(),
                                    sqlite3_errmsg(connection.handle())));
    }
    throw;
  }
}

int createSchema(Connection& connection) {
  connection.exec("BEGIN IMMEDIATE");
  try {
    if (singleInt(connection, "SELECT count(*) FROM sqlite_master") > 0) {
      connection.exec("COMMIT");
      return checkSchema(connection);
    }
    // The tables as both stores define them (internal/schema_sql.h).
    connection.exec(coreTablesSql(SqlDialect::kSqlite).c_str());
    connection.exec(
        (instancesTableSql(SqlDialect::kSqlite, "instances") + instancesIndexSql()).c_str());
    // The meta table names the writer and its schema; application_id and user_version repeat
    // them in the file header, where tools (and inspectFile) read them without SQL.
    connection.exec(fmt::format("INSERT INTO meta (key, value) VALUES ('schema_version', '{0}'), "
                                "('application', 'tessera'), "
                                "('created_utc', strftime('%Y-%m-%dT%H:%M:%SZ', 'now')); "
                                "PRAGMA application_id = {1}; PRAGMA user_version = {0};",
                                kSchemaVersion, kApplicationId)
                        .c_str());
    connection.exec("COMMIT");
    return kSchemaVersion;
  } catch (...) {
    connection.rollbackQuietly();
    throw;
  }
}

int migrateSchema(Connection& connection) {
  // IMMEDIATE: the version is read again under the write lock, so that of two processes
  // opening the same version-1 file only the first migrates it.
  connection.exec("BEGIN IMMEDIATE");
  try {
    static_assert(kSchemaVersion == 2, "add the migration to the new schema version here");
    const int version = checkSchema(connection);
    if (version == 1) {
      // SQLite cannot change a UNIQUE constraint in place: the table is built anew (the
      // order SQLite's documentation gives for other ALTER TABLE changes). Dropping the old
      // table drops its index too. Nothing refers to instances, so no foreign key moves.
      connection.exec(
          (instancesTableSql(SqlDialect::kSqlite, "instances_v2") +
           "INSERT INTO instances_v2 (run_id, patch_id, version, layer, texture_id, a, b, tx, "
           "ty, psnr_db, reused) SELECT run_id, patch_id, version, 0, texture_id, a, b, tx, ty, "
           "psnr_db, reused FROM instances; "
           "DROP TABLE instances; "
           "ALTER TABLE instances_v2 RENAME TO instances; " +
           instancesIndexSql())
              .c_str());
      Statement set_version(connection, "UPDATE meta SET value = ? WHERE key = 'schema_version'");
      set_version.bind(1, std::to_string(kSchemaVersion)).run();
      connection.exec(fmt::format("PRAGMA user_version = {}", kSchemaVersion).c_str());
    }
    connection.exec("COMMIT");
    return kSchemaVersion;
  } catch (const core::Error& e) {
    connection.rollbackQuietly();
    throw core::Error(fmt::format("{} (while migrating it to schema {}; the database is unchanged)",
                                  e.what(), kSchemaVersion));
  } catch (...) {
    connection.rollbackQuietly();
    throw;
  }
}

}  // namespace tessera::db::internal
