#pragma once
// Frames out onto a ROS 1 graph as a camera driver publishes them: depth and colour images
// with their camera_info, stamped with the graph's clock. `tessera play` uses it to stand in
// for a camera when testing a robot's nodes (tessera's own ros:// source among them).
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>

#include "tessera/core/frame.h"
#include "tessera/drivers/ros1/ros_topics.h"

namespace tessera::drivers::ros1 {

struct RosFramePublisherOptions {
  std::string master_uri;  // empty: ROS_MASTER_URI, else http://localhost:11311
  RosTopics topics = openniLaunchTopics();
  std::string depth_encoding = "16UC1";
  std::string colour_encoding = "rgb8";
  std::string frame_id = "camera_rgb_optical_frame";
  // "" publishes raw images; "png" or "jpeg" image_transport's compressed topics instead
  // (DEPTH/compressedDepth, COLOUR/compressed; compressed_image.h), as a robot's driver does
  // for nodes on other machines.
  std::string compressed;
};

class RosFramePublisher {
 public:
  // Throws core::SourceError naming a master that does not answer, core::ConfigError for an
  // encoding tessera does not write.
  explicit RosFramePublisher(const RosFramePublisherOptions& options);
  ~RosFramePublisher();

  // A frame's messages, encoded once (for a stand-in camera that should cost only the sending).
  struct Encoded;
  std::shared_ptr<const Encoded> encode(const core::Frame& frame) const;

  // Publishes the frame stamped `stamp_ns` (the graph's time, ns); its colour image keeps its
  // own offset from the depth image.
  void publish(const core::Frame& frame, std::int64_t stamp_ns);
  void publish(const Encoded& frame, std::int64_t stamp_ns);
  // The graph's time now, ns (wall time unless the graph runs on simulated time).
  static std::int64_t now();
  // Subscribers to the depth topic.
  std::size_t subscribers() const;

 private:
  struct Topics;
  RosFramePublisherOptions options_;
  std::unique_ptr<Topics> topics_;
  std::uint32_t seq_ = 0;
};

}  // namespace tessera::drivers::ros1
