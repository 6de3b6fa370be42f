#pragma once
// The topics an RGB-D camera publishes on a ROS 1 graph, and the sets tessera knows by name.
#include <optional>
#include <string>
#include <vector>

namespace tessera::drivers::ros1 {

struct RosTopics {
  std::string depth;
  std::string colour;
  std::string depth_info;   // sensor_msgs/CameraInfo of the depth image
  std::string colour_info;  // ... of the colour image
  std::string pose;         // ground truth: tf2_msgs/TFMessage or geometry_msgs/PoseStamped
};

// openni2_launch and freenect_launch with depth registration on (depth_registration:=true):
// registered 16UC1 depth and the colour camera's image_raw.
RosTopics openniLaunchTopics();
// The TUM RGB-D benchmark's bags: 32FC1 depth, rgb8 colour, ground truth on /tf.
RosTopics tumTopics();

// The named set ("openni" or "tum"); nothing for another name.
std::optional<RosTopics> namedTopics(const std::string& name);
std::string knownTopicSetNames();  // for --help and errors

// Applies remappings in ROS's own syntax, ROLE:=TOPIC, where ROLE is depth, colour,
// depth_info, colour_info or pose (an empty TOPIC drops the pose topic). Throws
// core::ConfigError naming a malformed one.
void remapTopics(RosTopics& topics, const std::vector<std::string>& remaps);

}  // namespace tessera::drivers::ros1
