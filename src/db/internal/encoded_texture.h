#pragma once
// A texture's columns encoded for either store, before any lock is taken (PNG encoding is the
// slow part of a commit).
#include <cstddef>
#include <string>

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

}  // namespace tessera::db::internal
