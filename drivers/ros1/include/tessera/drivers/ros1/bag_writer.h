#pragma once
// Writes tessera's frames as a ROS 1 bag (librosbag), laid out as a camera driver publishes
// them: depth and colour images with their camera_info, and the ground-truth pose on /tf.
#include <cstddef>
#include <filesystem>
#include <memory>
#include <string>

#include "tessera/core/frame.h"
#include "tessera/drivers/ros1/ros_topics.h"

namespace rosbag {
class Bag;
}

namespace tessera::drivers::ros1 {

struct BagWriterOptions {
  RosTopics topics = openniLaunchTopics();  // an empty pose topic writes no ground truth
  std::string depth_encoding = "16UC1";     // or 32FC1 metres
  std::string colour_encoding = "rgb8";     // or bgr8, a Bayer layout, yuv422, yuv422_yuy2
  std::string world_frame = "world";
  std::string depth_frame = "camera_rgb_optical_frame";   // registered depth: the colour camera
  std::string colour_frame = "camera_rgb_optical_frame";  // a separate colour camera: its own
  bool lz4 = false;                                       // compress chunks
  // "" writes raw images. "png" or "jpeg": image_transport's compressed topics instead, as
  // robots record them: depth on DEPTH/compressedDepth (16UC1 PNG, lossless), colour on
  // COLOUR/compressed in this format (compressed_image.h).
  std::string compressed;
};

// Not thread-safe: one writer thread.
class BagWriter {
 public:
  // Throws core::Error naming the file when it cannot be created, or core::ConfigError for an
  // encoding tessera does not write.
  BagWriter(const std::filesystem::path& path, const BagWriterOptions& options = {});
  ~BagWriter();  // closes the bag if close() was not called (errors are logged)
  BagWriter(const BagWriter&) = delete;
  BagWriter& operator=(const BagWriter&) = delete;

  // Appends one frame. Throws core::Error naming the file when the write fails (disk full).
  void write(const core::Frame& frame);
  // Writes the index. Throws core::Error naming the file when that fails.
  void close();

  std::size_t framesWritten() const { return frames_; }

 private:
  std::filesystem::path path_;
  BagWriterOptions options_;
  std::unique_ptr<rosbag::Bag> bag_;
  std::size_t frames_ = 0;
  bool wrote_static_ = false;
};

}  // namespace tessera::drivers::ros1
