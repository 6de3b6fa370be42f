#include "ros_publishing.h"

#include <fmt/format.h>

#include "tessera/core/error.h"
#ifdef TESSERA_HAVE_ROS1
#include "tessera/ros_publish/ros_map_publisher.h"
#endif

namespace tessera::cli {

std::unique_ptr<pipeline::RunListener> openMapPublisher(const RunArguments& args,
                                                        const std::string& source_spec,
                                                        const pipeline::MapMonitor& monitor) {
  constexpr std::string_view kScheme = "ros://";
  const bool ros_source = source_spec.rfind(kScheme, 0) == 0;
  const std::string target =
      args.publish.empty() ? (ros_source ? source_spec : "none") : args.publish;
  if (target == "none") return nullptr;
  if (target.rfind(kScheme, 0) != 0) {
    throw core::ConfigError(
        fmt::format("--publish {}: expected ros://[HOST:PORT] or none", args.publish));
  }
#ifdef TESSERA_HAVE_ROS1
  ros_publish::RosPublisherOptions options;
  options.master_uri = target.substr(kScheme.size());
  options.map_frame = args.map_frame;
  options.camera_frame = args.published_camera_frame;
  // Frames from the graph carry its clock; a replay's own clock means nothing to the graph.
  options.stamp_with_frame_time = ros_source;
  return std::make_unique<ros_publish::RosMapPublisher>(options, monitor, source_spec);
#else
  (void)monitor;
  throw core::ConfigError(fmt::format(
      "--publish {}: this tessera was built without ROS 1; install it with scripts/setup.sh and "
      "build again",
      target));
#endif
}

}  // namespace tessera::cli
