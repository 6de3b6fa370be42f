#pragma once
// A texture's columns encoded for either store, before any lock is taken (PNG encoding is the
// slow part of a commit).
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "internal/texture_codec.h"
#include "tessera/db/texture_record.h"

namespace tessera::db::internal {

struct EncodedTexture {
  const TextureRecord* record = nullptr;
  std::string content_key;
  Bytes png, ccv, keypoints, descriptors;
};

// Checks and encodes texture `index` of a commit to the store at `location`; throws
// core::Error naming both when the record cannot be stored.
EncodedTexture encodeTexture(const TextureRecord& record, const std::string& location,
                             std::size_t index);

// An instance as messages name it: "patch 3", or "patch 3 layer 1" for an overlay.
std::string instanceName(const TextureInstance& instance);

// The texture id an instance of a commit names: a stored texture's id as it is, or for a
// negative one the id given to the commit's new texture at index -id - 1 (`new_ids`). Throws
// core::Error naming `location` for a negative layer or an index beyond the commit's textures.
std::int64_t instanceTextureId(const TextureInstance& instance,
                               const std::vector<std::int64_t>& new_ids,
                               const std::string& location);

}  // namespace tessera::db::internal
