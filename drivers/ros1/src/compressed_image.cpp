#include "tessera/drivers/ros1/compressed_image.h"

#include <array>
#include <cmath>
#include <cstring>
#include <limits>

#include <fmt/format.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "tessera/core/error.h"

namespace tessera::drivers::ros1 {

namespace {

constexpr std::array<std::uint8_t, 8> kPngSignature = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
// The compressedDepth header: an int32 format, then the two quantisation floats. Transports
// before the format field wrote the floats alone.
constexpr std::size_t kDepthHeaderBytes = 12;
constexpr std::size_t kOldDepthHeaderBytes = 8;

bool pngAt(const std::vector<std::uint8_t>& data, std::size_t offset) {
  return data.size() >= offset + kPngSignature.size() &&
         std::memcmp(data.data() + offset, kPngSignature.data(), kPngSignature.size()) == 0;
}

// The image encoding before the format string's first ';' ("16UC1; compressedDepth png").
std::string encodingOf(const std::string& format) {
  const std::string head = format.substr(0, format.find(';'));
  const auto first = head.find_first_not_of(' ');
  const auto last = head.find_last_not_of(' ');
  return first == std::string::npos ? "" : head.substr(first, last - first + 1);
}

cv::Mat decoded(const std::vector<std::uint8_t>& data, std::size_t offset, int flags) {
  const cv::Mat bytes(1, static_cast<int>(data.size() - offset), CV_8UC1,
                      const_cast<std::uint8_t*>(data.data() + offset));
  try {
    return cv::imdecode(bytes, flags);
  } catch (const cv::Exception&) {
    return {};
  }
}

}  // namespace

std::string compressedTopic(const std::string& raw_topic, bool depth) {
  return raw_topic + (depth ? "/compressedDepth" : "/compressed");
}

cv::Mat depthFromCompressed(const sensor_msgs::CompressedImage& image) {
  if (image.format.find("compressedDepth") == std::string::npos) {
    throw core::SourceError(
        fmt::format("compressed image in format '{}' is not compressedDepth, the depth transport",
                    image.format));
  }
  const std::string encoding = encodingOf(image.format);
  if (encoding != "16UC1" && encoding != "32FC1") {
    throw core::SourceError(fmt::format(
        "compressedDepth image in encoding '{}'; tessera reads 16UC1 and 32FC1", encoding));
  }
  std::size_t offset = 0;
  if (pngAt(image.data, kDepthHeaderBytes)) {
    offset = kDepthHeaderBytes;
  } else if (pngAt(image.data, kOldDepthHeaderBytes)) {
    offset = kOldDepthHeaderBytes;
  } else {
    throw core::SourceError(fmt::format(
        "compressedDepth image ({} bytes) holds no PNG after its header (cut short, or RVL, "
        "which tessera does not read)",
        image.data.size()));
  }
  const cv::Mat png = decoded(image.data, offset, cv::IMREAD_UNCHANGED);
  if (png.empty() || png.type() != CV_16UC1) {
    throw core::SourceError("compressedDepth image's PNG is cut short or not 16-bit grey");
  }
  if (encoding == "16UC1") return png;
  // 32FC1: quantised inverse depth; a and b are the header's last two floats.
  float a = 0.0F, b = 0.0F;
  std::memcpy(&a, image.data.data() + offset - 8, sizeof a);
  std::memcpy(&b, image.data.data() + offset - 4, sizeof b);
  cv::Mat depth(png.size(), CV_16UC1);
  for (int y = 0; y < png.rows; ++y) {
    const auto* in = png.ptr<std::uint16_t>(y);
    auto* out = depth.ptr<std::uint16_t>(y);
    for (int x = 0; x < png.cols; ++x) {
      const double mm =
          in[x] == 0 ? 0.0 : std::round(1000.0 * a / (static_cast<double>(in[x]) - b));
      const bool usable =
          std::isfinite(mm) && mm > 0.0 && mm <= std::numeric_limits<std::uint16_t>::max();
      out[x] = usable ? static_cast<std::uint16_t>(mm) : 0;
    }
  }
  return depth;
}

cv::Mat colourFromCompressed(const sensor_msgs::CompressedImage& image) {
  const cv::Mat bgr = image.data.empty() ? cv::Mat() : decoded(image.data, 0, cv::IMREAD_COLOR);
  if (bgr.empty()) {
    throw core::SourceError(
        fmt::format("compressed colour image in format '{}' ({} bytes) cannot be decoded",
                    image.format, image.data.size()));
  }
  cv::Mat rgb;
  cv::cvtColor(bgr, rgb, cv::COLOR_BGR2RGB);
  return rgb;
}

sensor_msgs::CompressedImage compressedFromDepth(const cv::Mat& depth_mm) {
  if (depth_mm.type() != CV_16UC1) {
    throw core::Error("compressedFromDepth: depth must be CV_16UC1 millimetres");
  }
  sensor_msgs::CompressedImage message;
  message.format = "16UC1; compressedDepth png";
  std::vector<std::uint8_t> png;
  cv::imencode(".png", depth_mm, png);
  // Format 0 (inverse depth); the quantisation floats are unused for 16UC1.
  message.data.assign(kDepthHeaderBytes, 0);
  message.data.insert(message.data.end(), png.begin(), png.end());
  return message;
}

sensor_msgs::CompressedImage compressedFromColour(const cv::Mat& rgb, const std::string& format) {
  if (format != "jpeg" && format != "png") {
    throw core::ConfigError(
        fmt::format("compressed colour format '{}': tessera writes jpeg or png", format));
  }
  if (rgb.type() != CV_8UC3) throw core::Error("compressedFromColour: colour must be CV_8UC3");
  cv::Mat bgr;
  cv::cvtColor(rgb, bgr, cv::COLOR_RGB2BGR);
  sensor_msgs::CompressedImage message;
  message.format = fmt::format("rgb8; {} compressed bgr8", format);
  const std::vector<int> parameters =
      format == "jpeg" ? std::vector<int>{cv::IMWRITE_JPEG_QUALITY, 95} : std::vector<int>{};
  cv::imencode(format == "jpeg" ? ".jpg" : ".png", bgr, message.data, parameters);
  return message;
}

}  // namespace tessera::drivers::ros1
