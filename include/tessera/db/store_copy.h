#pragma once
// Copying one texture database into another, between the stores (SQLite <-> PostgreSQL): a
// robot's local database merged into its fleet's, or a fleet's taken along offline.
#include <cstddef>
#include <functional>

#include "tessera/db/texture_store.h"

namespace tessera::db {

struct CopyReport {
  std::size_t runs_copied = 0;
  std::size_t runs_already_there = 0;  // copied by an earlier `db copy`
  std::size_t textures_copied = 0;
  std::size_t textures_already_there = 0;  // the same pixels were stored (content key)
  std::size_t instances_copied = 0;
};

// (textures done, textures in all)
using CopyProgress = std::function<void(std::size_t, std::size_t)>;

// Adds everything `from` holds to `to`. Each run becomes a run of `to` whose source names where
// it came from ("<source> [copied: run <id> started <UTC time>]"); a run copied before is not
// copied again, so copying twice, or again after an interruption, adds nothing twice.
// Textures whose pixels `to` already has are not stored again; instances follow the ids.
// Textures are read one at a time and written in commits of at most 32.
CopyReport copyStore(const TextureStore& from, TextureStore& to, const CopyProgress& progress = {});

}  // namespace tessera::db
