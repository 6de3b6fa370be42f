#include "tessera/drivers/ros1/ros_frame_publisher.h"

#include <ros/ros.h>

#include "internal/message_codec.h"
#include "tessera/drivers/ros1/compressed_image.h"
#include "tessera/drivers/ros1/ros_image.h"
#include "tessera/drivers/ros1/ros_node.h"

namespace tessera::drivers::ros1 {

namespace {

// Publishes a copy of an encoded message with this publication's header.
template <typename Message>
void publishWith(const ros::Publisher& publisher, Message message, const std_msgs::Header& header) {
  message.header = header;
  publisher.publish(message);
}

}  // namespace

struct RosFramePublisher::Topics {
  ros::Publisher depth, colour, depth_info, colour_info;
};

RosFramePublisher::RosFramePublisher(const RosFramePublisherOptions& options)
    : options_(options), topics_(std::make_unique<Topics>()) {
  // Fail on a bad encoding before anything is advertised.
  imageFromDepth(cv::Mat(1, 2, CV_16UC1, cv::Scalar(1)), options_.depth_encoding);
  imageFromColour(cv::Mat(2, 2, CV_8UC3, cv::Scalar(1, 2, 3)), options_.colour_encoding);
  const bool compressed = !options_.compressed.empty();
  if (compressed) {
    compressedFromColour(cv::Mat(2, 2, CV_8UC3, cv::Scalar(1, 2, 3)), options_.compressed);
    if (options_.depth_encoding != "16UC1") {
      throw core::ConfigError(
          fmt::format("compressed topics carry 16UC1 depth (compressedDepth PNG), not {}",
                      options_.depth_encoding));
    }
  }
  ensureRosNode(options_.master_uri);
  ros::NodeHandle node;
  if (compressed) {
    topics_->depth = node.advertise<sensor_msgs::CompressedImage>(
        compressedTopic(options_.topics.depth, true), 2);
    topics_->colour = node.advertise<sensor_msgs::CompressedImage>(
        compressedTopic(options_.topics.colour, false), 2);
  } else {
    topics_->depth = node.advertise<sensor_msgs::Image>(options_.topics.depth, 2);
    topics_->colour = node.advertise<sensor_msgs::Image>(options_.topics.colour, 2);
  }
  topics_->depth_info = node.advertise<sensor_msgs::CameraInfo>(options_.topics.depth_info, 2);
  topics_->colour_info = node.advertise<sensor_msgs::CameraInfo>(options_.topics.colour_info, 2);
}

RosFramePublisher::~RosFramePublisher() {
  for (ros::Publisher* p :
       {&topics_->depth, &topics_->colour, &topics_->depth_info, &topics_->colour_info}) {
    p->shutdown();
  }
}

// Raw or compressed images, as the options say; the headers are set when published.
struct RosFramePublisher::Encoded {
  std::int64_t colour_offset_ns = 0;
  sensor_msgs::CameraInfo depth_info, colour_info;
  sensor_msgs::Image depth, colour;
  sensor_msgs::CompressedImage compressed_depth, compressed_colour;
};

std::shared_ptr<const RosFramePublisher::Encoded> RosFramePublisher::encode(
    const core::Frame& frame) const {
  auto encoded = std::make_shared<Encoded>();
  encoded->colour_offset_ns =
      frame.colour_timestamp_ns ? *frame.colour_timestamp_ns - frame.timestamp_ns : 0;
  encoded->depth_info = cameraInfoFromIntrinsics(frame.intrinsics);
  encoded->colour_info = cameraInfoFromIntrinsics(
      frame.colour_camera ? frame.colour_camera->intrinsics : frame.intrinsics);
  if (options_.compressed.empty()) {
    encoded->depth = imageFromDepth(frame.depth_mm, options_.depth_encoding);
    encoded->colour = imageFromColour(frame.rgb, options_.colour_encoding);
  } else {
    encoded->compressed_depth = compressedFromDepth(frame.depth_mm);
    encoded->compressed_colour = compressedFromColour(frame.rgb, options_.compressed);
  }
  return encoded;
}

void RosFramePublisher::publish(const core::Frame& frame, std::int64_t stamp_ns) {
  publish(*encode(frame), stamp_ns);
}

void RosFramePublisher::publish(const Encoded& frame, std::int64_t stamp_ns) {
  std_msgs::Header header;
  header.seq = seq_++;
  header.stamp = rosTime(stamp_ns);
  header.frame_id = options_.frame_id;
  std_msgs::Header colour_header = header;
  colour_header.stamp = rosTime(stamp_ns + frame.colour_offset_ns);
  const bool compressed = !options_.compressed.empty();
  // Colour first: a subscriber pairs each depth image with colour that has already come.
  publishWith(topics_->colour_info, frame.colour_info, colour_header);
  if (compressed) {
    publishWith(topics_->colour, frame.compressed_colour, colour_header);
  } else {
    publishWith(topics_->colour, frame.colour, colour_header);
  }
  publishWith(topics_->depth_info, frame.depth_info, header);
  if (compressed) {
    publishWith(topics_->depth, frame.compressed_depth, header);
  } else {
    publishWith(topics_->depth, frame.depth, header);
  }
}

std::int64_t RosFramePublisher::now() {
  return static_cast<std::int64_t>(ros::Time::now().toNSec());
}

std::size_t RosFramePublisher::subscribers() const { return topics_->depth.getNumSubscribers(); }

}  // namespace tessera::drivers::ros1
