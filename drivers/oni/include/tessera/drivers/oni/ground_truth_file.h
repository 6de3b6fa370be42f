#pragma once
// The ground-truth sidecar of a recording (OUT.gt.json): intrinsics and per-frame camera poses,
// plus whatever a synthetic scene adds (planes, textures). OniSource reads it back.
#include <filesystem>
#include <optional>

#include <nlohmann/json.hpp>

#include "tessera/core/frame.h"

namespace tessera::drivers::oni {

// Collects what the sidecar says about each recorded frame. Not thread-safe.
class GroundTruthFile {
 public:
  void setIntrinsics(const core::Intrinsics& intrinsics);
  void addFrame(const core::Frame& frame);
  // Further top-level keys (e.g. "planes"); must not be "intrinsics" or "frames".
  nlohmann::json& extra() { return extra_; }
  std::size_t framesWithPose() const { return frames_with_pose_; }

  // Writes the JSON file; throws core::Error naming it when that fails.
  void write(const std::filesystem::path& path) const;

 private:
  nlohmann::json intrinsics_;
  nlohmann::json frames_ = nlohmann::json::array();
  nlohmann::json extra_ = nlohmann::json::object();
  std::size_t frames_with_pose_ = 0;
};

// Pose as the sidecar stores it: [tx, ty, tz, qx, qy, qz, qw] (TUM order).
nlohmann::json poseToJson(const core::Isometry& T);

}  // namespace tessera::drivers::oni
