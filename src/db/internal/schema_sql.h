#pragma once
// The texture database's tables, written once for both stores: SQLite (one robot) and
// PostgreSQL (a fleet). Only the column types differ between the two dialects; the tables,
// columns, constraints, index and schema version are the same, and so is the migration story
// (kSchemaVersion in tessera/db/texture_store.h: an older schema is migrated when opened for
// writing, a newer one refused).
#include <string>

namespace tessera::db::internal {

enum class SqlDialect { kSqlite, kPostgres };

// CREATE TABLE statements for meta, runs and textures (not instances: see instancesTableSql).
std::string coreTablesSql(SqlDialect dialect);
// CREATE TABLE `name` for the instances table (the migration from schema 1 builds it under a
// temporary name), and the index textures() counts uses with.
std::string instancesTableSql(SqlDialect dialect, const std::string& name);
std::string instancesIndexSql();

// Removes one texture (parameter 1) when run parameter 2 stored it and no instance uses it
// (TextureStore::removeUnused).
std::string removeUnusedTextureSql(SqlDialect dialect);

}  // namespace tessera::db::internal
