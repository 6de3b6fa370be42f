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

std::string instanceName(const TextureInstance& instance) {
  return instance.layer == 0
             ? fmt::format("patch {}", instance.patch_id)
             : fmt::format("patch {} layer {}", instance.patch_id, instance.layer);
}

std::int64_t instanceTextureId(const TextureInstance& instance,
                               const std::vector<std::int64_t>& new_ids,
                               const std::string& location) {
  if (instance.layer < 0) {
    throw core::Error(fmt::format("{}: the instance of {} has a negative layer (0 is the patch's "
                                  "texture, 1.. its overlays)",
                                  location, instanceName(instance)));
  }
  if (instance.texture_id >= 0) return instance.texture_id;
  const auto index = static_cast<std::size_t>(-(instance.texture_id + 1));
  if (index >= new_ids.size()) {
    throw core::Error(fmt::format("{}: the instance of {} refers to new texture {}, but the "
                                  "commit has {}",
                                  location, instanceName(instance), index, new_ids.size()));
  }
  return new_ids[index];
}

}  // namespace tessera::db::internal
