#include "tessera/texture/bitmap_export.h"

#include <fmt/format.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "tessera/core/error.h"

namespace tessera::texture {

namespace {

// Written beside `path` and renamed over it: a reader never sees half a file, and a second
// name for the old file (a saved map's) keeps the old pixels.
void writePng(const std::filesystem::path& path, const cv::Mat& image) {
  const std::filesystem::path writing =
      path.parent_path() / (path.stem().string() + ".writing" + path.extension().string());
  bool written = false;
  try {
    written = cv::imwrite(writing.string(), image);
  } catch (const cv::Exception& e) {
    throw core::Error(fmt::format("{}: could not be written: {}", path.string(), e.what()));
  }
  std::error_code ec;
  if (written) std::filesystem::rename(writing, path, ec);
  if (!written || ec) {
    std::filesystem::remove(writing, ec);
    throw core::Error(fmt::format("{}: could not be written (disk full?)", path.string()));
  }
}

}  // namespace

cv::Mat bgraImage(const cv::Mat& rgb, const cv::Mat& mask) {
  cv::Mat bgra;
  cv::cvtColor(rgb, bgra, cv::COLOR_RGB2BGRA);  // alpha 255
  if (!mask.empty()) cv::insertChannel(mask, bgra, 3);
  return bgra;
}

void writeRgbaPng(const std::filesystem::path& path, const cv::Mat& rgb, const cv::Mat& mask) {
  writePng(path, bgraImage(rgb, mask));
}

planes::TextureBinding bindingOf(const PatchBitmap& bitmap, const std::string& image,
                                 const std::string& state_image) {
  planes::TextureBinding binding;
  binding.version = bitmap.version;
  binding.image = image;
  binding.state_image = state_image;
  binding.texel_m = bitmap.grid.texel_m;
  binding.origin_uv = bitmap.grid.origin_uv;
  binding.x_axis = bitmap.grid.x_axis;
  binding.y_axis = bitmap.grid.y_axis;
  binding.width = bitmap.grid.width;
  binding.height = bitmap.grid.height;
  binding.observed = bitmap.observed;
  binding.inpainted = bitmap.inpainted;
  return binding;
}

planes::TextureBinding writeBitmapFiles(const PatchBitmap& bitmap,
                                        const std::filesystem::path& out_dir) {
  const std::filesystem::path folder = out_dir / "textures";
  std::error_code ec;
  std::filesystem::create_directories(folder, ec);
  if (ec) {
    throw core::Error(fmt::format("{}: cannot be created: {}", folder.string(), ec.message()));
  }
  const std::string image = fmt::format("textures/patch_{}.png", bitmap.id);
  const std::string state = fmt::format("textures/patch_{}_state.png", bitmap.id);
  writeRgbaPng(out_dir / image, bitmap.image, bitmap.state != static_cast<int>(TexelState::kEmpty));
  writePng(out_dir / state, bitmap.state);
  return bindingOf(bitmap, image, state);
}

planes::TextureBindings currentBindings(const planes::TextureBindings& written,
                                        const planes::PatchMap& map,
                                        const std::filesystem::path& out_dir) {
  planes::TextureBindings current;
  for (const auto& [id, binding] : written) {
    const planes::Patch* patch = map.find(id);
    if (patch != nullptr && patch->finalized && patch->version == binding.version) {
      current.emplace(id, binding);
      continue;
    }
    std::error_code ignored;
    std::filesystem::remove(out_dir / binding.image, ignored);
    std::filesystem::remove(out_dir / binding.state_image, ignored);
  }
  return current;
}

void readBitmapImages(const std::filesystem::path& image, const std::filesystem::path& state_image,
                      cv::Mat& rgb, cv::Mat& state) {
  const cv::Mat bgra = cv::imread(image.string(), cv::IMREAD_UNCHANGED);
  if (bgra.empty() || bgra.type() != CV_8UC4) {
    throw core::Error(fmt::format("{}: missing or not an RGBA PNG", image.string()));
  }
  cv::cvtColor(bgra, rgb, cv::COLOR_BGRA2RGB);
  state = cv::imread(state_image.string(), cv::IMREAD_UNCHANGED);
  if (state.empty() || state.type() != CV_8UC1 || state.size() != rgb.size()) {
    throw core::Error(fmt::format("{}: missing, not a grey PNG or not the size of {}",
                                  state_image.string(), image.string()));
  }
}

}  // namespace tessera::texture
