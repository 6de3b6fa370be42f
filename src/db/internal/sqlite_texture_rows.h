#pragma once
// A texture's row in an SQLite textures table (internal/schema_sql.h), written and read the
// same way by the SQLite store and by the commit journal of a server's store.
#include <cstdint>

#include "internal/encoded_texture.h"
#include "internal/sqlite_connection.h"
#include "tessera/db/texture_record.h"

namespace tessera::db::internal {

// 17 parameters in the order of insertTexture's binds.
extern const char* const kInsertTexture;
// The columns recordOf reads, of the texture with id = ?1.
extern const char* const kSelectTexture;

// Inserts `encoded` with `insert` (prepared from kInsertTexture on `db`); returns its rowid.
std::int64_t insertTexture(Statement& insert, Connection& db, const EncodedTexture& encoded);

// The current row of kSelectTexture as a record; throws core::Error with the reason when a
// column does not decode.
TextureRecord recordOf(const Statement& row, std::int64_t id);

}  // namespace tessera::db::internal
