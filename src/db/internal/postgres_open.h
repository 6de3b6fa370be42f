#pragma once
// What the rest of the db module needs of the PostgreSQL store, without libpqxx's headers.
#include <memory>
#include <string>

#include "tessera/db/texture_store.h"

namespace tessera::db::internal {

// True for postgresql:// and postgres:// locations.
bool isPostgresUrl(const std::string& location);

// Opens (creating or migrating the schema when writable) the database at `url`.
std::unique_ptr<TextureStore> openPostgresStore(const std::string& url, const OpenOptions& options);

// `url` without a password: postgresql://user:secret@host/db -> postgresql://user@host/db, and
// a password=... parameter dropped.
std::string redactedUrl(const std::string& url);

}  // namespace tessera::db::internal
