#pragma once
// Live frames from a ROS 1 graph: `ros://` subscribes to a camera driver's depth and colour
// images and their camera_info through the master in ROS_MASTER_URI, `ros://HOST:PORT`
// through the master at http://HOST:PORT.
#include <atomic>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>

#include "tessera/core/frame_source.h"
#include "tessera/drivers/ros1/ros_topics.h"

namespace tessera::drivers::ros1 {

struct RosSourceOptions {
  std::string master_uri;  // empty: ROS_MASTER_URI, else http://localhost:11311
  RosTopics topics = openniLaunchTopics();
  std::optional<core::Intrinsics> intrinsics;       // overrides camera_info
  std::optional<core::ColourCamera> colour_camera;  // unregistered colour (--calibration)
  std::int64_t pair_tolerance_ns = 20'000'000;
  int frame_timeout_ms = 2000;        // no depth image for this long: the publisher stopped
  double reconnect_timeout_s = 10.0;  // how long a stopped publisher is waited for
  std::size_t queue_frames = 2;       // depth images held for a busy pipeline; older ones drop
  const std::atomic<bool>* stop = nullptr;  // set (Ctrl-C) to end the stream
};

// The master URI in "ros://[HOST:PORT]" (empty for the environment's); nothing for other
// sources.
std::optional<std::string> parseRosUri(const std::string& source);

// Opens the subscriptions. Throws core::SourceError naming the master when it cannot be
// reached. Depth images are paired with the colour image nearest in stamp; a publisher that
// stops gives one kInterrupted result, and the next read() waits reconnect_timeout_s for it.
std::unique_ptr<core::FrameSource> openRosSource(const RosSourceOptions& options);

}  // namespace tessera::drivers::ros1
