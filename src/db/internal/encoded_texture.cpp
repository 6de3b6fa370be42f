#include "internal/encoded_texture.h"

#include <fmt/format.h>

#include "tessera/core/error.h"

namespace tessera::db::internal {

EncodedTexture encodeTexture(const TextureRecord& record, const std::string& location,
                             std::size_t index) {
  const auto refuse = [&](const char* why) {
    return core::Error(
        fmt::format("{}: cannot commit texture {} of the commit: {}", location, index, why));
  };
  if (record.rgb.empty() || record.rgb.type() != CV_8UC3) throw refuse("rgb is not CV_8UC3");
  if (!record.mask.empty() &&
      (record.mask.type() != CV_8UC1 || record.mask.size() != record.rgb.size())) {
    throw refuse("mask is not CV_8UC1 of the rgb's size");
  }
  if (!record.descriptors.empty() &&
      static_cast<std::size_t>(record.descriptors.rows) != record.keypoints.size()) {
    throw refuse("descriptors need one row per keypoint");
  }
  EncodedTexture encoded;
  encoded.record = &record;
  // Always computed here, never taken from the record, so that the key matches the pixels.
  encoded.content_key = contentKey(record.rgb, record.mask);
  encoded.png = encodePng(record.rgb, record.mask);
  encoded.ccv = encodeFloats(record.ccv);
  encoded.keypoints = encodeKeypoints(record.keypoints);
  encoded.descriptors = encodeDescriptors(record.descriptors);
  return encoded;
}

}  // namespace tessera::db::internal
