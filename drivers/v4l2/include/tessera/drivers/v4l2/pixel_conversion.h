#pragma once
// From the bytes a V4L2 node delivers to the images a core::Frame holds.
#include <string>

#include <opencv2/core/mat.hpp>

#include "tessera/drivers/v4l2/v4l2_capture.h"

namespace tessera::drivers::v4l2 {

// Z16 or Y16 (16-bit little-endian, both read as millimetres) -> CV_16UC1 millimetres.
// Returns an empty Mat, with `problem` set, when the bytes cannot be a frame of `format`.
cv::Mat depthToMillimetres(const PixelFormat& format, const cv::Mat& bytes, std::string& problem);

// YUYV (BT.601, as OpenCV's COLOR_YUV2RGB_YUYV), MJPEG or RGB24 -> CV_8UC3 in R, G, B order.
// A corrupt or truncated JPEG, or a decoded size other than the format's, is an empty Mat with
// `problem` set.
cv::Mat colourToRgb(const PixelFormat& format, const cv::Mat& bytes, std::string& problem);

}  // namespace tessera::drivers::v4l2
