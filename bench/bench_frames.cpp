#include "bench_frames.h"

#include <filesystem>

#include <fmt/format.h>

#include "tessera/core/error.h"
#include "tessera/core/registration.h"
#include "tessera/drivers/dataset_source.h"
#include "tessera/drivers/oni/oni_source.h"

namespace tessera::bench {

namespace fs = std::filesystem;

std::string resolvedSource(const std::string& path) {
  if (!path.empty()) return path;
  const fs::path shared = fs::path(TESSERA_SOURCE_DIR) / "../shared/data/rgbd/tum_fr1_rpy_40";
  return fs::is_directory(shared)
             ? shared.lexically_normal().string()
             : (fs::path(TESSERA_SOURCE_DIR) / "recordings/tum_fr1_rpy_20.oni").string();
}

std::unique_ptr<core::FrameSource> openSource(const std::string& path,
                                              const std::optional<core::Intrinsics>& intrinsics,
                                              const std::optional<double>& depth_units_per_m) {
  const std::string resolved = resolvedSource(path);
  if (fs::path(resolved).extension() == ".oni") {
    drivers::oni::OniSourceOptions options;
    options.intrinsics = intrinsics;
    return std::make_unique<drivers::oni::OniSource>(resolved, options);
  }
  drivers::DatasetOptions options;
  options.intrinsics = intrinsics;
  options.depth_units_per_m = depth_units_per_m;
  return std::make_unique<drivers::DatasetSource>(resolved, options);
}

std::vector<core::Frame> loadFrames(const std::string& path, std::size_t max_frames,
                                    bool need_truth,
                                    const std::optional<core::Intrinsics>& intrinsics,
                                    const std::optional<double>& depth_units_per_m) {
  const auto source = openSource(path, intrinsics, depth_units_per_m);
  std::vector<core::Frame> frames;
  while (max_frames == 0 || frames.size() < max_frames) {
    core::ReadResult result = source->read();
    if (result.status == core::ReadStatus::kEndOfData) break;
    if (result.status == core::ReadStatus::kBadFrame) continue;
    if (need_truth && !result.frame.T_W_C_gt) {
      throw core::Error(
          fmt::format("{}: frame {} has no ground-truth pose", source->name(), result.frame.index));
    }
    frames.push_back(core::withRegisteredColour(std::move(result.frame)));
  }
  if (frames.empty()) throw core::Error(fmt::format("{}: no frames", source->name()));
  return frames;
}

core::ReadResult MemorySource::read() {
  core::ReadResult result;
  if (next_ == frames_.size()) return result;  // kEndOfData
  result.status = core::ReadStatus::kFrame;
  result.frame = frames_[next_++];  // cv::Mat copies share pixels: cheap
  return result;
}

}  // namespace tessera::bench
