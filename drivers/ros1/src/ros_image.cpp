#include "tessera/drivers/ros1/ros_image.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>

#include <fmt/format.h>
#include <opencv2/imgproc.hpp>

#include "tessera/core/error.h"

namespace tessera::drivers::ros1 {

namespace {

struct ColourLayout {
  const char* encoding;
  int type;    // OpenCV type of the message's data
  int to_rgb;  // cv::cvtColor code to RGB; -1: already RGB
};

// OpenCV names a Bayer pattern by the second row's second and third pixels, ROS by the
// first 2x2 block: ROS rggb is OpenCV's BG, and so on.
constexpr ColourLayout kColourLayouts[] = {
    {"rgb8", CV_8UC3, -1},
    {"bgr8", CV_8UC3, cv::COLOR_BGR2RGB},
    {"rgba8", CV_8UC4, cv::COLOR_RGBA2RGB},
    {"bgra8", CV_8UC4, cv::COLOR_BGRA2RGB},
    {"mono8", CV_8UC1, cv::COLOR_GRAY2RGB},
    {"bayer_rggb8", CV_8UC1, cv::COLOR_BayerBG2RGB},
    {"bayer_bggr8", CV_8UC1, cv::COLOR_BayerRG2RGB},
    {"bayer_gbrg8", CV_8UC1, cv::COLOR_BayerGR2RGB},
    {"bayer_grbg8", CV_8UC1, cv::COLOR_BayerGB2RGB},
    {"yuv422", CV_8UC2, cv::COLOR_YUV2RGB_UYVY},
    {"yuv422_yuy2", CV_8UC2, cv::COLOR_YUV2RGB_YUYV},
};

// The message's pixels as a Mat of `type` (no copy), after checking the sizes agree.
cv::Mat wrap(const sensor_msgs::Image& image, int type) {
  const std::size_t row_bytes =
      static_cast<std::size_t>(image.width) * static_cast<std::size_t>(CV_ELEM_SIZE(type));
  if (image.width == 0 || image.height == 0) {
    throw core::SourceError(
        fmt::format("{} image is empty ({}x{})", image.encoding, image.width, image.height));
  }
  if (image.step < row_bytes ||
      image.data.size() < static_cast<std::size_t>(image.step) * image.height) {
    throw core::SourceError(
        fmt::format("{} image {}x{}: {} bytes of data with row step {}, too few for its size",
                    image.encoding, image.width, image.height, image.data.size(), image.step));
  }
  return cv::Mat(static_cast<int>(image.height), static_cast<int>(image.width), type,
                 const_cast<std::uint8_t*>(image.data.data()), image.step);
}

bool hostIsBigEndian() {
  const std::uint16_t probe = 1;
  std::uint8_t first = 0;
  std::memcpy(&first, &probe, 1);
  return first == 0;
}

// Each pixel of a Bayer mosaic keeps the channel its filter passes: `pattern` names the
// filters of the 2x2 block from the top left, e.g. "rggb".
cv::Mat mosaic(const cv::Mat& rgb, const std::string& pattern) {
  cv::Mat out(rgb.size(), CV_8UC1);
  const auto channel = [](char filter) { return filter == 'r' ? 0 : filter == 'g' ? 1 : 2; };
  for (int y = 0; y < rgb.rows; ++y) {
    for (int x = 0; x < rgb.cols; ++x) {
      const char filter = pattern[static_cast<std::size_t>((y % 2) * 2 + x % 2)];
      out.at<std::uint8_t>(y, x) = rgb.at<cv::Vec3b>(y, x)[channel(filter)];
    }
  }
  return out;
}

std::uint8_t clampByte(double v) {
  return static_cast<std::uint8_t>(std::clamp(std::lround(v), 0L, 255L));
}

// BT.601 studio range, two pixels per four bytes: U Y0 V Y1 (uyvy) or Y0 U Y1 V (yuyv),
// chroma from the mean of the pair.
cv::Mat packYuv422(const cv::Mat& rgb, bool uyvy) {
  cv::Mat out(rgb.rows, rgb.cols, CV_8UC2);
  for (int y = 0; y < rgb.rows; ++y) {
    std::uint8_t* row = out.ptr<std::uint8_t>(y);
    for (int x = 0; x + 1 < rgb.cols; x += 2) {
      double luma[2], u = 0.0, v = 0.0;
      for (int i = 0; i < 2; ++i) {
        const cv::Vec3b p = rgb.at<cv::Vec3b>(y, x + i);
        const double r = p[0], g = p[1], b = p[2];
        luma[i] = 16.0 + 0.257 * r + 0.504 * g + 0.098 * b;
        u += 0.5 * (128.0 - 0.148 * r - 0.291 * g + 0.439 * b);
        v += 0.5 * (128.0 + 0.439 * r - 0.368 * g - 0.071 * b);
      }
      std::uint8_t* q = row + 2 * x;
      if (uyvy) {
        q[0] = clampByte(u), q[1] = clampByte(luma[0]), q[2] = clampByte(v),
        q[3] = clampByte(luma[1]);
      } else {
        q[0] = clampByte(luma[0]), q[1] = clampByte(u), q[2] = clampByte(luma[1]),
        q[3] = clampByte(v);
      }
    }
  }
  return out;
}

sensor_msgs::Image messageFrom(const cv::Mat& pixels, const std::string& encoding) {
  sensor_msgs::Image image;
  image.encoding = encoding;
  image.width = static_cast<std::uint32_t>(pixels.cols);
  image.height = static_cast<std::uint32_t>(pixels.rows);
  image.is_bigendian = hostIsBigEndian() ? 1 : 0;
  image.step = static_cast<std::uint32_t>(pixels.cols * static_cast<int>(pixels.elemSize()));
  image.data.resize(static_cast<std::size_t>(image.step) * image.height);
  cv::Mat view(pixels.rows, pixels.cols, pixels.type(), image.data.data(), image.step);
  pixels.copyTo(view);
  return image;
}

}  // namespace

std::string readableColourEncodings() {
  std::string names;
  for (const ColourLayout& layout : kColourLayouts) {
    if (!names.empty()) names += ", ";
    names += layout.encoding;
  }
  return names;
}

bool readsDepthEncoding(const std::string& encoding) {
  return encoding == "16UC1" || encoding == "mono16" || encoding == "32FC1";
}

bool readsColourEncoding(const std::string& encoding) {
  return std::any_of(std::begin(kColourLayouts), std::end(kColourLayouts),
                     [&](const ColourLayout& layout) { return encoding == layout.encoding; });
}

cv::Mat depthFromImage(const sensor_msgs::Image& image) {
  if (image.encoding == "16UC1" || image.encoding == "mono16") {
    cv::Mat depth = wrap(image, CV_16UC1).clone();
    if ((image.is_bigendian != 0) != hostIsBigEndian()) {
      for (int y = 0; y < depth.rows; ++y) {
        auto* row = depth.ptr<std::uint16_t>(y);
        for (int x = 0; x < depth.cols; ++x) {
          row[x] = static_cast<std::uint16_t>((row[x] >> 8) | (row[x] << 8));
        }
      }
    }
    return depth;
  }
  if (image.encoding == "32FC1") {
    if ((image.is_bigendian != 0) != hostIsBigEndian()) {
      throw core::SourceError("32FC1 depth in the other byte order is not supported");
    }
    const cv::Mat metres = wrap(image, CV_32FC1);
    cv::Mat depth(metres.size(), CV_16UC1);
    for (int y = 0; y < depth.rows; ++y) {
      const float* in = metres.ptr<float>(y);
      auto* out = depth.ptr<std::uint16_t>(y);
      for (int x = 0; x < depth.cols; ++x) {
        const double mm = std::round(static_cast<double>(in[x]) * 1000.0);
        const bool usable =
            std::isfinite(mm) && mm > 0.0 && mm <= std::numeric_limits<std::uint16_t>::max();
        out[x] = usable ? static_cast<std::uint16_t>(mm) : 0;
      }
    }
    return depth;
  }
  throw core::SourceError(fmt::format(
      "depth image encoding '{}' is not a depth encoding tessera reads (16UC1 or mono16 "
      "millimetres, 32FC1 metres)",
      image.encoding));
}

cv::Mat colourFromImage(const sensor_msgs::Image& image) {
  for (const ColourLayout& layout : kColourLayouts) {
    if (image.encoding != layout.encoding) continue;
    const cv::Mat pixels = wrap(image, layout.type);
    if (layout.to_rgb < 0) return pixels.clone();
    cv::Mat rgb;
    cv::cvtColor(pixels, rgb, layout.to_rgb);
    return rgb;
  }
  throw core::SourceError(fmt::format("colour image encoding '{}' is not one tessera reads ({})",
                                      image.encoding, readableColourEncodings()));
}

sensor_msgs::Image imageFromDepth(const cv::Mat& depth_mm, const std::string& encoding) {
  CV_Assert(depth_mm.type() == CV_16UC1);
  if (encoding == "16UC1") return messageFrom(depth_mm, encoding);
  if (encoding == "32FC1") {
    cv::Mat metres(depth_mm.size(), CV_32FC1);
    for (int y = 0; y < depth_mm.rows; ++y) {
      const auto* in = depth_mm.ptr<std::uint16_t>(y);
      float* out = metres.ptr<float>(y);
      for (int x = 0; x < depth_mm.cols; ++x) {
        out[x] = in[x] == 0 ? std::numeric_limits<float>::quiet_NaN()
                            : static_cast<float>(in[x]) / 1000.0f;
      }
    }
    return messageFrom(metres, encoding);
  }
  throw core::ConfigError(
      fmt::format("depth encoding '{}': tessera writes 16UC1 or 32FC1", encoding));
}

sensor_msgs::Image imageFromColour(const cv::Mat& rgb, const std::string& encoding) {
  CV_Assert(rgb.type() == CV_8UC3);
  if (encoding == "rgb8") return messageFrom(rgb, encoding);
  if (encoding == "bgr8") {
    cv::Mat bgr;
    cv::cvtColor(rgb, bgr, cv::COLOR_RGB2BGR);
    return messageFrom(bgr, encoding);
  }
  if (encoding.rfind("bayer_", 0) == 0 && encoding.size() == 11) {
    return messageFrom(mosaic(rgb, encoding.substr(6, 4)), encoding);
  }
  if (encoding == "yuv422" || encoding == "yuv422_yuy2") {
    return messageFrom(packYuv422(rgb, encoding == "yuv422"), encoding);
  }
  throw core::ConfigError(fmt::format(
      "colour encoding '{}': tessera writes rgb8, bgr8, bayer_rggb8, bayer_bggr8, bayer_gbrg8, "
      "bayer_grbg8, yuv422 or yuv422_yuy2",
      encoding));
}

core::Intrinsics intrinsicsFromCameraInfo(const sensor_msgs::CameraInfo& info) {
  core::Intrinsics intrinsics;
  intrinsics.width = static_cast<int>(info.width);
  intrinsics.height = static_cast<int>(info.height);
  intrinsics.fx = info.K[0];
  intrinsics.fy = info.K[4];
  intrinsics.cx = info.K[2];
  intrinsics.cy = info.K[5];
  return intrinsics;
}

sensor_msgs::CameraInfo cameraInfoFromIntrinsics(const core::Intrinsics& intrinsics) {
  sensor_msgs::CameraInfo info;
  info.width = static_cast<std::uint32_t>(intrinsics.width);
  info.height = static_cast<std::uint32_t>(intrinsics.height);
  info.distortion_model = "plumb_bob";
  info.D.assign(5, 0.0);
  info.K = {intrinsics.fx, 0.0, intrinsics.cx, 0.0, intrinsics.fy, intrinsics.cy, 0.0, 0.0, 1.0};
  info.R = {1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0};
  info.P = {intrinsics.fx, 0.0, intrinsics.cx, 0.0, 0.0, intrinsics.fy,
            intrinsics.cy, 0.0, 0.0,           0.0, 1.0, 0.0};
  return info;
}

}  // namespace tessera::drivers::ros1
