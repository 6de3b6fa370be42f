#pragma once
// Patch bitmaps as files: an RGBA PNG per patch (alpha 0 where the bitmap has no colour) and a
// grey PNG of each texel's state, under OUT/textures/.
#include <filesystem>
#include <map>

#include "tessera/planes/texture_binding.h"
#include "tessera/texture/bitmap_builder.h"

namespace tessera::texture {

// Writes out_dir/textures/patch_<id>.png and patch_<id>_state.png (replacing an earlier
// version's) and returns where the bitmap lies on its patch (for patches.obj and
// patches.json). Throws core::Error naming a file that cannot be written.
planes::TextureBinding writeBitmapFiles(const PatchBitmap& bitmap,
                                        const std::filesystem::path& out_dir);

// The bindings among `written` whose patch is finalized in `map` at their version; the files of
// the others (patches merged away since) are removed.
planes::TextureBindings currentBindings(const planes::TextureBindings& written,
                                        const planes::PatchMap& map,
                                        const std::filesystem::path& out_dir);

// An RGB image (CV_8UC3) as BGRA for OpenCV's PNG writer, its alpha `mask` (CV_8UC1), or
// opaque when `mask` is empty.
cv::Mat bgraImage(const cv::Mat& rgb, const cv::Mat& mask);

// An RGB image (CV_8UC3) as an RGBA PNG whose alpha is `mask` (CV_8UC1). Throws core::Error
// naming the file when it cannot be written.
void writeRgbaPng(const std::filesystem::path& path, const cv::Mat& rgb, const cv::Mat& mask);

// The placement of a bitmap on its patch, with the image names given.
planes::TextureBinding bindingOf(const PatchBitmap& bitmap, const std::string& image,
                                 const std::string& state_image);

// Reads a bitmap written by writeBitmaps back: the RGB image and the state, from the two
// PNGs (paths given). Throws core::Error naming a file that is missing or not such a PNG.
void readBitmapImages(const std::filesystem::path& image, const std::filesystem::path& state_image,
                      cv::Mat& rgb, cv::Mat& state);

}  // namespace tessera::texture
