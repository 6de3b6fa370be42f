#pragma once
// ROS 1 bag files (.bag) as a frame source, read with librosbag: depth and colour images paired
// by their header time stamps, intrinsics from camera_info, ground-truth poses from a tf or
// pose topic. A bag whose index is missing or cut off plays what its records hold.
#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>

#include "tessera/core/frame_source.h"
#include "tessera/drivers/ros1/ros_topics.h"

namespace tessera::drivers::ros1 {

struct BagSourceOptions {
  // Nothing: the first known set (openni, then tum) whose depth and colour topics the bag has.
  std::optional<RosTopics> topics;
  bool pose_named = false;  // the pose topic was named: its absence is an error, not a warning
  std::optional<core::Intrinsics> intrinsics;       // overrides camera_info
  std::optional<core::ColourCamera> colour_camera;  // unregistered colour (--calibration)
  std::string world_frame = "world";  // ground truth: the pose of the camera in this frame
  std::string camera_frame;           // ... of this frame; empty: the depth images' frame_id
  std::int64_t pair_tolerance_ns = 20'000'000;  // depth and colour stamps at most this apart
};

bool isBagPath(const std::filesystem::path& path);

// Throws core::SourceError naming the file when it is not a bag, or lacks the topics (listing
// those it has), or its depth topic has no camera_info and no --intrinsics are given.
std::unique_ptr<core::FrameSource> openBagSource(const std::filesystem::path& path,
                                                 const BagSourceOptions& options = {});

}  // namespace tessera::drivers::ros1
