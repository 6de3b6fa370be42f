#pragma once
// Removing the textures no instance uses from a texture database: the superseded versions of
// patches that builds before TextureStore::removeUnused left behind.
#include <cstddef>

#include "tessera/db/texture_store.h"

namespace tessera::db {

struct PruneReport {
  std::size_t removed = 0;
  std::size_t png_bytes = 0;        // the removed textures' stored size
  std::size_t kept_unfinished = 0;  // unused, but their run is not finished
  std::size_t textures_left = 0;
};

// Removes every texture a finished run stored that no instance uses. Imported textures stay,
// and so do a run's still going (it may use them yet). Throws core::Error naming the database
// when it cannot write.
PruneReport pruneUnused(TextureStore& store);

}  // namespace tessera::db
