#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include "tessera/core/error.h"
#include "tessera/core/output_file.h"
#include "tessera/pipeline/stages.h"
#include "tessera/texture/bitmap_export.h"

namespace tessera::pipeline {

void BitmapFiles::keep(std::optional<texture::PatchBitmap> built) {
  if (!built) return;
  texture::PatchBitmap& bitmap = *built;
  timer_.add(bitmap.build_ms);
  area_built_m2_ += bitmap.area_m2();
  // Versions of one patch come in finalization order (the commit stage's): the newest wins.
  const auto bytesOf = [](int width, int height) {
    return 3 * static_cast<std::size_t>(width) * static_cast<std::size_t>(height);
  };
  if (const auto it = written_.find(bitmap.id); it != written_.end()) {
    bitmap_bytes_ -= bytesOf(it->second.width, it->second.height);
    const std::lock_guard lock(written_mutex_);
    written_.erase(it);
  }
  if (const auto it = unwritten_.find(bitmap.id); it != unwritten_.end()) {
    bitmap_bytes_ -= bytesOf(it->second.grid.width, it->second.grid.height);
    unwritten_.erase(it);
  }
  bitmap_bytes_ += bytesOf(bitmap.grid.width, bitmap.grid.height);
  try {
    planes::TextureBinding binding = texture::writeBitmapFiles(bitmap, out_dir_);
    const std::lock_guard lock(written_mutex_);
    written_.emplace(bitmap.id, std::move(binding));
  } catch (const core::Error& e) {  // kept, and tried again at the end
    spdlog::error("patch {} version {}: {}; its bitmap stays in memory", bitmap.id, bitmap.version,
                  e.what());
    unwritten_.emplace(bitmap.id, std::move(bitmap));
  }
}

void BitmapFiles::adopt(const planes::TextureBindings& earlier) {
  const std::lock_guard lock(written_mutex_);
  for (const auto& [id, binding] : earlier) {
    if (written_.emplace(id, binding).second) {
      bitmap_bytes_ += 3 * static_cast<std::size_t>(binding.width) * binding.height;
    }
  }
}

void BitmapFiles::flush() {
  for (auto it = unwritten_.begin(); it != unwritten_.end(); it = unwritten_.erase(it)) {
    planes::TextureBinding binding = texture::writeBitmapFiles(it->second, out_dir_);
    const std::lock_guard lock(written_mutex_);
    written_.emplace(it->first, std::move(binding));
  }
}

planes::TextureBindings BitmapFiles::linkCurrentInto(const std::filesystem::path& dir,
                                                     const std::map<int, int>& versions) const {
  planes::TextureBindings linked;
  std::filesystem::create_directories(dir / "textures");
  // Under the lock: keep() drops a binding before it writes the files of the next version,
  // so a binding found here names its own version's files.
  const std::lock_guard lock(written_mutex_);
  for (const auto& [id, binding] : written_) {
    const auto version = versions.find(id);
    if (version == versions.end() || version->second != binding.version) continue;
    for (const std::string& file : {binding.image, binding.state_image}) {
      try {
        core::linkOrCopy(out_dir_ / file, dir / file);
      } catch (const std::filesystem::filesystem_error& e) {
        throw core::Error(fmt::format("{}: cannot be kept in the map: {}", file, e.what()));
      }
    }
    linked.emplace(id, binding);
  }
  return linked;
}

}  // namespace tessera::pipeline
