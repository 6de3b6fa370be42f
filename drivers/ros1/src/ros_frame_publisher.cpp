#include "tessera/drivers/ros1/ros_frame_publisher.h"

#include <ros/ros.h>

#include "internal/message_codec.h"
#include "tessera/drivers/ros1/compressed_image.h"
#include "tessera/drivers/ros1/ros_image.h"
#include "tessera/drivers/ros1/ros_node.h"

namespace tessera::drivers::ros1 {

struct RosFramePublisher::Topics {
  ros::Publisher depth, colour, depth_info, colour_info;
};

RosFramePublisher::RosFramePublisher(const RosFramePublisherOptions& options)
    : options_(options), topics_(std::make_unique<Topics>()) {
  // Fail on a bad encoding before anything is advertised.
  imageFromDepth(cv::Mat(1, 2, CV_16UC1, cv::Scalar(1)), options_.depth_encoding);
  imageFromColour(cv::Mat(2, 2, CV_8UC3, cv::Scalar(1, 2, 3)), options_.colour_encoding);
  const bool compressed = !options_.compressed.empty();
  if (compressed) compressedFromColour(cv::Mat(2, 2, CV_8UC3), options_.compressed);
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

void RosFramePublisher::publish(const core::Frame& frame, std::int64_t stamp_ns) {
  const std::int64_t colour_offset =
      frame.colour_timestamp_ns ? *frame.colour_timestamp_ns - frame.timestamp_ns : 0;
  std_msgs::Header header;
  header.seq = seq_++;
  header.stamp = rosTime(stamp_ns);
  header.frame_id = options_.frame_id;
  sensor_msgs::CameraInfo info = cameraInfoFromIntrinsics(frame.intrinsics);
  info.header = header;
  std_msgs::Header colour_header = header;
  colour_header.stamp = rosTime(stamp_ns + colour_offset);
  sensor_msgs::CameraInfo colour_info = cameraInfoFromIntrinsics(
      frame.colour_camera ? frame.colour_camera->intrinsics : frame.intrinsics);
  colour_info.header = colour_header;
  // Colour first: a subscriber pairs each depth image with colour that has already come.
  topics_->colour_info.publish(colour_info);
  if (options_.compressed.empty()) {
    sensor_msgs::Image colour = imageFromColour(frame.rgb, options_.colour_encoding);
    colour.header = colour_header;
    topics_->colour.publish(colour);
  } else {
    sensor_msgs::CompressedImage colour = compressedFromColour(frame.rgb, options_.compressed);
    colour.header = colour_header;
    topics_->colour.publish(colour);
  }
  topics_->depth_info.publish(info);
  if (options_.compressed.empty()) {
    sensor_msgs::Image depth = imageFromDepth(frame.depth_mm, options_.depth_encoding);
    depth.header = header;
    topics_->depth.publish(depth);
  } else {
    sensor_msgs::CompressedImage depth = compressedFromDepth(frame.depth_mm);
    depth.header = header;
    topics_->depth.publish(depth);
  }
}

std::int64_t RosFramePublisher::now() {
  return static_cast<std::int64_t>(ros::Time::now().toNSec());
}

std::size_t RosFramePublisher::subscribers() const { return topics_->depth.getNumSubscribers(); }

}  // namespace tessera::drivers::ros1
