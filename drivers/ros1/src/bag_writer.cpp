#include "tessera/drivers/ros1/bag_writer.h"

#include <algorithm>

#include <fmt/format.h>
#include <rosbag/bag.h>
#include <spdlog/spdlog.h>
#include <tf2_msgs/TFMessage.h>

#include "internal/message_codec.h"
#include "tessera/core/error.h"
#include "tessera/drivers/ros1/compressed_image.h"
#include "tessera/drivers/ros1/ros_image.h"

namespace tessera::drivers::ros1 {

namespace {

// A bag refuses messages recorded at time zero; a recording whose clock starts at zero keeps
// its header stamps and is recorded a nanosecond later.
ros::Time recordTime(std::int64_t ns) { return rosTime(std::max<std::int64_t>(ns, 1)); }

}  // namespace

BagWriter::BagWriter(const std::filesystem::path& path, const BagWriterOptions& options)
    : path_(path), options_(options), bag_(std::make_unique<rosbag::Bag>()) {
  // Fail on a bad encoding before the file exists.
  const cv::Mat probe_depth(2, 2, CV_16UC1, cv::Scalar(1000));
  const cv::Mat probe_colour(2, 2, CV_8UC3, cv::Scalar(1, 2, 3));
  imageFromDepth(probe_depth, options_.depth_encoding);
  imageFromColour(probe_colour, options_.colour_encoding);
  if (!options_.compressed.empty()) {
    compressedFromColour(probe_colour, options_.compressed);
    if (options_.depth_encoding != "16UC1") {
      throw core::ConfigError(
          fmt::format("compressed bags carry 16UC1 depth (compressedDepth PNG), not {}",
                      options_.depth_encoding));
    }
  }
  try {
    bag_->open(path.string(), rosbag::bagmode::Write);
    bag_->setCompression(options_.lz4 ? rosbag::compression::LZ4
                                      : rosbag::compression::Uncompressed);
  } catch (const rosbag::BagException& e) {
    throw core::Error(fmt::format("{}: cannot create the bag: {}", path.string(), e.what()));
  }
}

BagWriter::~BagWriter() {
  try {
    close();
  } catch (const core::Error& e) {
    spdlog::error("{}", e.what());
  }
}

void BagWriter::write(const core::Frame& frame) {
  const std::int64_t colour_ns = frame.colour_timestamp_ns.value_or(frame.timestamp_ns);
  const std::string& colour_frame =
      frame.colour_camera ? options_.colour_frame : options_.depth_frame;
  try {
    std_msgs::Header depth_header;
    depth_header.seq = static_cast<std::uint32_t>(frames_);
    depth_header.stamp = rosTime(frame.timestamp_ns);
    depth_header.frame_id = options_.depth_frame;
    sensor_msgs::CameraInfo depth_info = cameraInfoFromIntrinsics(frame.intrinsics);
    depth_info.header = depth_header;
    if (options_.compressed.empty()) {
      sensor_msgs::Image depth = imageFromDepth(frame.depth_mm, options_.depth_encoding);
      depth.header = depth_header;
      bag_->write(options_.topics.depth, recordTime(frame.timestamp_ns), depth);
    } else {
      sensor_msgs::CompressedImage depth = compressedFromDepth(frame.depth_mm);
      depth.header = depth_header;
      bag_->write(compressedTopic(options_.topics.depth, true), recordTime(frame.timestamp_ns),
                  depth);
    }
    bag_->write(options_.topics.depth_info, recordTime(frame.timestamp_ns), depth_info);

    std_msgs::Header colour_header = depth_header;
    colour_header.stamp = rosTime(colour_ns);
    colour_header.frame_id = colour_frame;
    sensor_msgs::CameraInfo colour_info = cameraInfoFromIntrinsics(
        frame.colour_camera ? frame.colour_camera->intrinsics : frame.intrinsics);
    colour_info.header = colour_header;
    if (options_.compressed.empty()) {
      sensor_msgs::Image colour = imageFromColour(frame.rgb, options_.colour_encoding);
      colour.header = colour_header;
      bag_->write(options_.topics.colour, recordTime(colour_ns), colour);
    } else {
      sensor_msgs::CompressedImage colour = compressedFromColour(frame.rgb, options_.compressed);
      colour.header = colour_header;
      bag_->write(compressedTopic(options_.topics.colour, false), recordTime(colour_ns), colour);
    }
    bag_->write(options_.topics.colour_info, recordTime(colour_ns), colour_info);

    if (frame.colour_camera && !wrote_static_) {
      // Where the colour camera sits in the depth camera's frame: T_D_RGB = T_RGB_D^-1.
      geometry_msgs::TransformStamped link;
      link.header.stamp = depth_header.stamp;
      link.header.frame_id = options_.depth_frame;
      link.child_frame_id = options_.colour_frame;
      link.transform = transformFromIsometry(frame.colour_camera->T_RGB_D.inverse());
      tf2_msgs::TFMessage message;
      message.transforms.push_back(link);
      bag_->write("/tf_static", recordTime(frame.timestamp_ns), message);
      wrote_static_ = true;
    }
    if (frame.T_W_C_gt && !options_.topics.pose.empty()) {
      geometry_msgs::TransformStamped pose;
      pose.header.stamp = depth_header.stamp;
      pose.header.frame_id = options_.world_frame;
      pose.child_frame_id = options_.depth_frame;
      pose.transform = transformFromIsometry(*frame.T_W_C_gt);
      tf2_msgs::TFMessage message;
      message.transforms.push_back(pose);
      bag_->write(options_.topics.pose, recordTime(frame.timestamp_ns), message);
    }
  } catch (const rosbag::BagException& e) {
    throw core::Error(
        fmt::format("{}: writing frame {} failed: {}", path_.string(), frames_, e.what()));
  }
  ++frames_;
}

void BagWriter::close() {
  if (!bag_->isOpen()) return;
  try {
    bag_->close();
  } catch (const rosbag::BagException& e) {
    throw core::Error(fmt::format("{}: closing the bag failed: {}", path_.string(), e.what()));
  }
}

}  // namespace tessera::drivers::ros1
