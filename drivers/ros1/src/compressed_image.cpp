#include "tessera/drivers/ros1/compressed_image.h"

#include <array>
#include <cmath>
#include <cstring>
#include <limits>
#include <optional>
#include <utility>

#include <fmt/format.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "tessera/core/error.h"
#include "tessera/drivers/ros1/ros_image.h"

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

std::uint32_t bigEndian(const std::uint8_t* p, int bytes) {
  std::uint32_t value = 0;
  for (int i = 0; i < bytes; ++i) value = (value << 8) | p[i];
  return value;
}

// The size a PNG (its IHDR chunk) or JPEG (its start-of-frame segment) at `offset` declares;
// nothing for anything else or when the header is cut short.
std::optional<std::pair<std::uint32_t, std::uint32_t>> declaredSize(
    const std::vector<std::uint8_t>& data, std::size_t offset) {
  const std::uint8_t* p = data.data() + offset;
  const std::size_t n = data.size() - offset;
  if (pngAt(data, offset)) {
    if (n < 24 || std::memcmp(p + 12, "IHDR", 4) != 0) return std::nullopt;
    return std::pair{bigEndian(p + 16, 4), bigEndian(p + 20, 4)};
  }
  if (n < 4 || p[0] != 0xFF || p[1] != 0xD8) return std::nullopt;
  // JPEG segments: FF, marker, then (but for the markers without one) a 2-byte length.
  std::size_t at = 2;
  while (at + 4 <= n) {
    if (p[at] != 0xFF) return std::nullopt;
    const std::uint8_t marker = p[at + 1];
    if (marker == 0xFF) {  // fill byte
      ++at;
      continue;
    }
    const bool start_of_frame =
        marker >= 0xC0 && marker <= 0xCF && marker != 0xC4 && marker != 0xC8 && marker != 0xCC;
    if (start_of_frame) {
      if (at + 9 > n) return std::nullopt;
      return std::pair{bigEndian(p + at + 7, 2), bigEndian(p + at + 5, 2)};
    }
    if (marker == 0x01 || (marker >= 0xD0 && marker <= 0xD7)) {
      at += 2;
    } else {
      at += 2 + bigEndian(p + at + 2, 2);
    }
  }
  return std::nullopt;
}

// The largest image a message may declare: far above any depth camera's, and small enough that
// a corrupt or hostile header cannot make the decoder allocate gigabytes.
constexpr std::uint32_t kMaxSide = 8192;
constexpr std::uint64_t kMaxPixels = 4096ULL * 4096ULL;

// The image decoded, or empty when it cannot be; throws core::SourceError when it is neither
// PNG nor JPEG or declares a size beyond the limits above.
cv::Mat decoded(const std::vector<std::uint8_t>& data, std::size_t offset, int flags) {
  const auto size = declaredSize(data, offset);
  if (!size) {
    throw core::SourceError(
        fmt::format("the {} bytes after the header are not a PNG or JPEG image (or are cut short "
                    "before its size)",
                    data.size() - offset));
  }
  const auto [width, height] = *size;
  if (width == 0 || height == 0 || width > kMaxSide || height > kMaxSide ||
      std::uint64_t{width} * height > kMaxPixels) {
    throw core::SourceError(fmt::format(
        "the image declares {} x {} pixels; tessera reads at most {} a side and {} in all", width,
        height, kMaxSide, kMaxPixels));
  }
  try {
    const cv::Mat bytes(1, static_cast<int>(data.size() - offset), CV_8UC1,
                        const_cast<std::uint8_t*>(data.data() + offset));
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
  cv::Mat png;
  try {
    png = decoded(image.data, offset, cv::IMREAD_UNCHANGED);
  } catch (const core::SourceError& e) {
    throw core::SourceError(fmt::format("compressedDepth image: {}", e.what()));
  }
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
  const std::string encoding = encodingOf(image.format);
  const bool mosaic = encoding.rfind("bayer_", 0) == 0;
  cv::Mat bgr;
  try {
    bgr = decoded(image.data, 0, mosaic ? cv::IMREAD_UNCHANGED : cv::IMREAD_COLOR);
  } catch (const core::SourceError& e) {
    throw core::SourceError(
        fmt::format("compressed colour image in format '{}': {}", image.format, e.what()));
  }
  if (mosaic && bgr.type() == CV_8UC1) {
    // The transport stores a Bayer mosaic as it is (PNG): demosaic it as a raw image is.
    sensor_msgs::Image raw;
    raw.encoding = encoding;
    raw.width = static_cast<std::uint32_t>(bgr.cols);
    raw.height = static_cast<std::uint32_t>(bgr.rows);
    raw.step = raw.width;
    raw.data.assign(bgr.datastart, bgr.dataend);
    return colourFromImage(raw);
  }
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
