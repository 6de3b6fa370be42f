#include "tessera/drivers/ros1/ros_topics.h"

#include <fmt/format.h>

#include "tessera/core/error.h"

namespace tessera::drivers::ros1 {

RosTopics openniLaunchTopics() {
  return {"/camera/depth_registered/image_raw", "/camera/rgb/image_raw",
          "/camera/depth_registered/camera_info", "/camera/rgb/camera_info", "/tf"};
}

RosTopics tumTopics() {
  return {"/camera/depth/image", "/camera/rgb/image_color", "/camera/depth/camera_info",
          "/camera/rgb/camera_info", "/tf"};
}

std::optional<RosTopics> namedTopics(const std::string& name) {
  if (name == "openni") return openniLaunchTopics();
  if (name == "tum") return tumTopics();
  return std::nullopt;
}

std::string knownTopicSetNames() { return "openni, tum"; }

void remapTopics(RosTopics& topics, const std::vector<std::string>& remaps) {
  for (const std::string& remap : remaps) {
    const auto at = remap.find(":=");
    const std::string role = at == std::string::npos ? "" : remap.substr(0, at);
    const std::string topic = at == std::string::npos ? "" : remap.substr(at + 2);
    std::string* slot = role == "depth"         ? &topics.depth
                        : role == "colour"      ? &topics.colour
                        : role == "depth_info"  ? &topics.depth_info
                        : role == "colour_info" ? &topics.colour_info
                        : role == "pose"        ? &topics.pose
                                                : nullptr;
    if (!slot || (topic.empty() && role != "pose")) {
      throw core::ConfigError(fmt::format(
          "--topic {}: expected ROLE:=TOPIC with ROLE one of depth, colour, depth_info, "
          "colour_info, pose",
          remap));
    }
    *slot = topic;
  }
}

}  // namespace tessera::drivers::ros1
