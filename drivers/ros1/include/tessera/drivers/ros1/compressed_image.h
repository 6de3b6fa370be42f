#pragma once
// sensor_msgs/CompressedImage, as image_transport's `compressed` and `compressedDepth`
// transports publish and robots record them, to and from tessera's images. Colour: JPEG or PNG
// (the transport encodes colour as bgr8). Depth: compressedDepth, a 12-byte header (format,
// two quantisation floats) then a 16-bit PNG: 16UC1 millimetres as they are, or 32FC1 as
// quantised inverse depth, depth = a / (v - b) with v = 0 for no depth.
#include <string>

#include <sensor_msgs/CompressedImage.h>
#include <opencv2/core/mat.hpp>

namespace tessera::drivers::ros1 {

inline constexpr const char* kCompressedImageType = "sensor_msgs/CompressedImage";

// The topic the transport publishes a raw image topic on: TOPIC/compressedDepth for depth,
// TOPIC/compressed for colour.
std::string compressedTopic(const std::string& raw_topic, bool depth);

// CV_16UC1 millimetres (0 = no depth). Throws core::SourceError naming what is wrong: not
// compressedDepth, an encoding other than 16UC1 or 32FC1, data cut short, not PNG (the newer
// RVL format is not read).
cv::Mat depthFromCompressed(const sensor_msgs::CompressedImage& image);

// CV_8UC3 in R, G, B order. Throws core::SourceError when the data is not an image.
cv::Mat colourFromCompressed(const sensor_msgs::CompressedImage& image);

// A depth image (CV_16UC1 millimetres) as compressedDepth "16UC1; compressedDepth png":
// lossless.
sensor_msgs::CompressedImage compressedFromDepth(const cv::Mat& depth_mm);

// An RGB image (CV_8UC3) as "rgb8; FORMAT compressed bgr8", FORMAT jpeg (quality 95, lossy)
// or png (lossless). Throws core::ConfigError for another format.
sensor_msgs::CompressedImage compressedFromColour(const cv::Mat& rgb, const std::string& format);

}  // namespace tessera::drivers::ros1
