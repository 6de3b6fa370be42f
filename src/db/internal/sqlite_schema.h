#pragma once
// The SQLite schema of the texture database, and the checks that decide whether a file is one
// this build may open. Every check that can refuse a file runs before anything writes to it.
#include <cstdint>
#include <filesystem>

#include "internal/sqlite_connection.h"

namespace tessera::db::internal {

// PRAGMA application_id of every tessera database: "TESS" in ASCII, so `file(1)` and other
// tools can tell it apart from other SQLite files.
constexpr std::int32_t kApplicationId = 0x54455353;

enum class FileState { kMissing, kEmpty, kDatabase };

// Looks at `path` with plain file reads, so that nothing is created or changed: kMissing,
// kEmpty (0 bytes), or kDatabase for a SQLite file that may be tessera's. Throws core::Error
// for a folder, an unreadable file, a file that is not SQLite, and, when the file's header is
// current (no pending -wal), for another application's database or a newer schema.
FileState inspectFile(const std::filesystem::path& path);

// Busy timeout for every connection; WAL mode, synchronous=FULL and foreign keys for the writer.
void configureReader(Connection& connection);
void configureWriter(Connection& connection);

// Checks through SQL that the database is tessera's and at most kSchemaVersion; returns its
// schema version. Throws core::Error naming the file otherwise (also when it is corrupt).
int checkSchema(Connection& connection);

// Creates the schema in a new, empty database (the writer connection); returns its version.
// When another process created it first, checks that one instead and returns its version
// (older when an older build created it: then migrateSchema follows).
int createSchema(Connection& connection);

// Brings a database of an older schema (checked by checkSchema) to kSchemaVersion in one
// transaction on the writer connection; returns kSchemaVersion. 1 -> 2: instances get a layer
// (0 for every existing row) and UNIQUE (run_id, patch_id, layer). A failure rolls everything
// back and throws core::Error naming the file. Never called for a read-only store: that reads
// the older schema as it is.
int migrateSchema(Connection& connection);

}  // namespace tessera::db::internal
