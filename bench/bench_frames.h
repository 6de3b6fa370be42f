#pragma once
// What the benchmarks share: the default recording to measure and frames held in memory.
#include <cstddef>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "tessera/core/frame.h"
#include "tessera/core/frame_source.h"

namespace tessera::bench {

// `path`, or when empty ../shared/data/rgbd/tum_fr1_rpy_40 if present, else the committed
// recordings/tum_fr1_rpy_20.oni.
std::string resolvedSource(const std::string& path);

// A dataset folder or an .oni recording; `intrinsics` overrides what the source carries, and
// `depth_units_per_m` a dataset folder's raw depth units per metre (tessera run --depth-scale;
// .oni recordings carry millimetres and ignore it).
std::unique_ptr<core::FrameSource> openSource(
    const std::string& path, const std::optional<core::Intrinsics>& intrinsics = std::nullopt,
    const std::optional<double>& depth_units_per_m = std::nullopt);

// Reads up to max_frames good frames (0: all), colour registered to depth. With need_truth,
// throws core::Error when a frame has no ground-truth pose.
std::vector<core::Frame> loadFrames(
    const std::string& path, std::size_t max_frames, bool need_truth,
    const std::optional<core::Intrinsics>& intrinsics = std::nullopt,
    const std::optional<double>& depth_units_per_m = std::nullopt);

// Replays frames held in memory, so that a measurement does not include decoding.
class MemorySource : public core::FrameSource {
 public:
  MemorySource(const std::vector<core::Frame>& frames, std::string name)
      : frames_(frames), name_(std::move(name)) {}
  core::ReadResult read() override;
  std::string name() const override { return name_; }
  std::optional<std::size_t> frameCount() const override { return frames_.size(); }

 private:
  const std::vector<core::Frame>& frames_;
  std::string name_;
  std::size_t next_ = 0;
};

}  // namespace tessera::bench
