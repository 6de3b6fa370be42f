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
  // For colour from its own camera: its intrinsics and T_RGB_D.
  void setColourCamera(const core::ColourCamera& camera);
  void addFrame(const core::Frame& frame);
  // Further top-level keys (e.g. "planes"); must not be "intrinsics" or "frames".
  nlohmann::json& extra() { return extra_; }
  std::size_t framesWithPose() const { return frames_with_pose_; }

  // Writes the JSON file; throws core::Error naming it when that fails.
  void write(const std::filesystem::path& path) const;

 private:
  nlohmann::json intrinsics_;
  nlohmann::json colour_camera_;  // null when colour is registered to depth
  nlohmann::json frames_ = nlohmann::json::array();
  nlohmann::json extra_ = nlohmann::json::object();
  std::size_t frames_with_pose_ = 0;
};

// Pose as the sidecar stores it: [tx, ty, tz, qx, qy, qz, qw] (TUM order).
nlohmann::json poseToJson(const core::Isometry& T);
// The inverse: nothing unless the value is such a list of seven numbers.
std::optional<core::Isometry> poseFromJson(const nlohmann::json& value);

nlohmann::json intrinsicsToJson(const core::Intrinsics& k);
core::Intrinsics intrinsicsFromJson(const nlohmann::json& value);

}  // namespace tessera::drivers::oni
