// PatchMap's patch lifecycle: finalization when a patch stops growing or leaves the view, and
// colour samples moved out of memory while a finalized patch is out of view.
#include <chrono>
#include <filesystem>

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include "tessera/core/error.h"
#include "tessera/planes/patch_map.h"

namespace tessera::planes {

void PatchMap::finalize(Patch& patch, std::vector<PatchEvent>& events, const char* reason) const {
  patch.version += 1;
  patch.finalized = true;
  patch.finalized_area_m2 = areaM2(patch);
  events.push_back(
      {PatchEvent::Kind::kFinalized, patch.id, patch.version, patch.finalized_area_m2, reason});
}

bool PatchMap::largeEnough(const Patch& patch, double area_m2) const {
  // A tile finalized before stays in the map when a move within its plane left it smaller: its
  // earlier version would otherwise stay published over what moved away.
  return area_m2 >= config_.min_area_m2 || (patch.version > 0 && area_m2 > 0.0);
}

std::vector<PatchEvent> PatchMap::endFrame(long frame_index) {
  std::vector<PatchEvent> events = std::move(pending_);
  pending_.clear();
  for (auto& [id, patch] : patches_) {
    const double area = areaM2(patch);
    // A tile of a plane whose moves within it are still to come is textured after them.
    const bool settled = patch.frames_to_settle == 0 && moving_planes_.count(patch.plane) == 0;
    if (patch.frames_to_settle > 0) --patch.frames_to_settle;
    if (seen_this_frame_.count(patch.id) == 0) {
      const bool gone_long = frame_index - patch.last_seen_frame >= config_.out_of_view_frames;
      if (!patch.finalized && settled && gone_long && largeEnough(patch, area)) {
        finalize(patch, events, "out of view");
      }
      continue;
    }
    patch.last_seen_frame = frame_index;
    patch.frames_seen += 1;
    patch.area_in_view.push_back(area);
    while (patch.area_in_view.size() > static_cast<std::size_t>(config_.stable_frames) + 1) {
      patch.area_in_view.pop_front();
    }
    if (patch.finalized && area > patch.finalized_area_m2 * (1.0 + config_.max_growth)) {
      patch.finalized = false;  // it grows again: a new version will follow
    }
    const bool stable =
        patch.area_in_view.size() > static_cast<std::size_t>(config_.stable_frames) &&
        area <= patch.area_in_view.front() * (1.0 + config_.max_growth);
    if (!patch.finalized && settled && stable && largeEnough(patch, area))
      finalize(patch, events, "stable");
  }
  seen_this_frame_.clear();
  return events;
}

void PatchMap::setSampleSpillDir(std::filesystem::path dir) {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) {
    spdlog::warn("{}: cannot create it ({}); colour samples stay in memory", dir.string(),
                 ec.message());
    return;
  }
  spill_dir_ = std::move(dir);
}

std::size_t PatchMap::releaseIdleSamples(long frame_index) {
  if (!spill_dir_ || config_.release_samples_after_frames <= 0 || spill_failed_) return 0;
  std::size_t released = 0;
  for (auto& [id, patch] : patches_) {
    if (!patch.finalized || patch.spilled_samples || patch.samples->size() == 0 ||
        frame_index - patch.last_seen_frame < config_.release_samples_after_frames) {
      continue;
    }
    const std::filesystem::path path = *spill_dir_ / fmt::format("patch_{}.samples", patch.id);
    try {
      patch.samples->save(path);
    } catch (const core::Error& e) {
      spdlog::warn("{}; colour samples stay in memory from now on", e.what());
      spill_failed_ = true;
      std::error_code ec;
      std::filesystem::remove(path, ec);
      break;
    }
    patch.samples = ColourSamples(config_.sample_cell_m, config_.sample_views);
    patch.spilled_samples = path;
    ++released;
  }
  samples_released_ += released;
  return released;
}

void PatchMap::restoreSamples(Patch& patch) const {
  if (!patch.spilled_samples) return;
  try {
    const auto start = std::chrono::steady_clock::now();
    patch.samples = ColourSamples::load(*patch.spilled_samples);
    spdlog::debug(
        "patch {}: colour samples read back ({:.1f} MB) in {:.0f} ms", patch.id,
        static_cast<double>(patch.samples->bytes()) / 1e6,
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
            .count());
  } catch (const core::Error& e) {  // the patch goes on with the samples it gets from now
    spdlog::error("patch {}: {}; its earlier colours are lost", patch.id, e.what());
  }
  std::error_code ec;
  std::filesystem::remove(*patch.spilled_samples, ec);
  patch.spilled_samples.reset();
}

std::vector<PatchEvent> PatchMap::finalizeAll() {
  // Tiles still owed a move within their plane are textured where the correction puts them.
  while (!moving_planes_.empty()) finishMovesWithin(*moving_planes_.begin());
  std::vector<PatchEvent> events = std::move(pending_);
  pending_.clear();
  for (auto& [id, patch] : patches_) {
    if (!patch.finalized && largeEnough(patch, areaM2(patch))) {
      finalize(patch, events, "end of stream");
    }
  }
  return events;
}

}  // namespace tessera::planes
