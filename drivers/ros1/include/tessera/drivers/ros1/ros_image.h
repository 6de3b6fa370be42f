#pragma once
// sensor_msgs/Image and sensor_msgs/CameraInfo to and from tessera's images and intrinsics.
// Depth: 16UC1 (or mono16) millimetres, 32FC1 metres. Colour: rgb8, bgr8, rgba8, bgra8, mono8,
// the four 8-bit Bayer layouts (bayer_rggb8, bayer_bggr8, bayer_gbrg8, bayer_grbg8) and packed
// YUV 4:2:2 (yuv422 = UYVY, yuv422_yuy2 = YUYV), which is what openni2_camera and
// freenect_camera publish.
#include <string>

#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <opencv2/core/mat.hpp>

#include "tessera/core/intrinsics.h"

namespace tessera::drivers::ros1 {

// The colour encodings colourFromImage() reads, comma-separated, for messages and --help.
std::string readableColourEncodings();

// Whether depthFromImage() / colourFromImage() read images in `encoding`: a topic in another
// one is of no use, which is worth one error rather than a skipped frame per image.
bool readsDepthEncoding(const std::string& encoding);
bool readsColourEncoding(const std::string& encoding);

// CV_16UC1 millimetres (0 = no depth). 32FC1 metres are rounded to millimetres; NaN, infinite,
// non-positive and beyond-range values become 0. Throws core::SourceError naming the
// encoding when it is not a depth encoding or the data is shorter than the header says.
cv::Mat depthFromImage(const sensor_msgs::Image& image);

// CV_8UC3 in R, G, B order. Throws core::SourceError as above.
cv::Mat colourFromImage(const sensor_msgs::Image& image);

// A depth image (CV_16UC1 millimetres) as 16UC1, bit for bit, or as 32FC1 metres (0 -> NaN,
// as depth_image_proc writes missing depth).
sensor_msgs::Image imageFromDepth(const cv::Mat& depth_mm, const std::string& encoding);

// An RGB image (CV_8UC3) in `encoding`: rgb8, bgr8, a Bayer layout (each pixel keeps the one
// channel its filter passes) or yuv422 / yuv422_yuy2 (BT.601, studio range).
sensor_msgs::Image imageFromColour(const cv::Mat& rgb, const std::string& encoding);

// K's focal lengths and principal point with the message's size; invalid (fx = 0) when the
// driver published no calibration.
core::Intrinsics intrinsicsFromCameraInfo(const sensor_msgs::CameraInfo& info);
sensor_msgs::CameraInfo cameraInfoFromIntrinsics(const core::Intrinsics& intrinsics);

}  // namespace tessera::drivers::ros1
