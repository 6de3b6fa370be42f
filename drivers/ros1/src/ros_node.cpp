#include "tessera/drivers/ros1/ros_node.h"

#include <cstdlib>
#include <map>
#include <memory>
#include <mutex>

#include <fmt/format.h>
#include <ros/ros.h>

#include "tessera/core/error.h"

namespace tessera::drivers::ros1 {

namespace {

std::mutex started_mutex;
std::string started_master;                        // guarded by started_mutex
std::unique_ptr<ros::AsyncSpinner> spinner;        // guarded by started_mutex
std::unique_ptr<ros::NodeHandle> keep_node_alive;  // guarded by started_mutex

}  // namespace

std::string resolveMasterUri(const std::string& master_uri) {
  if (!master_uri.empty()) {
    return master_uri.rfind("http://", 0) == 0 ? master_uri : "http://" + master_uri;
  }
  if (const char* env = std::getenv("ROS_MASTER_URI"); env != nullptr && *env != '\0') return env;
  return "http://localhost:11311";
}

void ensureRosNode(const std::string& master_uri) {
  const std::string master = resolveMasterUri(master_uri);
  std::lock_guard lock(started_mutex);
  if (!started_master.empty()) {
    if (started_master != master) {
      throw core::ConfigError(
          fmt::format("ros://: this process already talks to the master at {}, not {}",
                      started_master, master));
    }
    return;
  }
  std::map<std::string, std::string> remappings = {{"__master", master}};
  ros::init(remappings, "tessera",
            ros::init_options::AnonymousName | ros::init_options::NoSigintHandler |
                ros::init_options::NoRosout);
  if (!ros::master::check()) {
    throw core::SourceError(fmt::format(
        "ros://: no ROS master answers at {}; start one (roscore, or rosmaster --core) or name "
        "it with ros://HOST:PORT or ROS_MASTER_URI",
        master));
  }
  ros::start();
  keep_node_alive = std::make_unique<ros::NodeHandle>();
  spinner = std::make_unique<ros::AsyncSpinner>(2);
  spinner->start();
  started_master = master;
}

}  // namespace tessera::drivers::ros1
