#include "internal/texture_codec.h"

#include <bit>
#include <cstring>
#include <string>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "tessera/core/error.h"

namespace tessera::db::internal {

TextureKind parseKind(const std::string& text) {
  if (text == "single") return TextureKind::kSingle;
  if (text == "pattern") return TextureKind::kPattern;
  throw core::Error("unknown kind '" + text + "'");
}

// The blobs are written with memcpy of native values; a big-endian port would need byte swaps
// in put()/get() to keep reading databases written on x86 and ARM.
static_assert(std::endian::native == std::endian::little, "blob formats are little-endian");

namespace {

constexpr std::uint8_t kKeypointFormat = 1;
constexpr std::size_t kKeypointBytes = 5 * sizeof(float) + 2 * sizeof(std::int32_t);
constexpr std::size_t kDescriptorHeaderBytes = 3 * sizeof(std::int32_t);

// B G R A <-> (R G B, mask): channel pairs for cv::mixChannels, the same both ways.
constexpr int kBgraToRgbMask[] = {0, 2, 1, 1, 2, 0, 3, 3};

template <typename T>
void put(Bytes& out, T value) {
  const std::size_t at = out.size();
  out.resize(at + sizeof(T));
  std::memcpy(out.data() + at, &value, sizeof(T));
}

// Reads values front to back and refuses to read past the end.
class Reader {
 public:
  Reader(const void* data, std::size_t bytes)
      : data_(static_cast<const std::uint8_t*>(data)), bytes_(bytes) {}
  template <typename T>
  T get() {
    T value;
    need(sizeof(T));
    std::memcpy(&value, data_ + at_, sizeof(T));
    at_ += sizeof(T);
    return value;
  }
  void copyTo(void* out, std::size_t bytes) {
    need(bytes);
    if (bytes > 0) std::memcpy(out, data_ + at_, bytes);
    at_ += bytes;
  }
  std::size_t remaining() const { return bytes_ - at_; }

 private:
  void need(std::size_t bytes) const {
    if (bytes > remaining()) throw core::Error("blob shorter than its contents");
  }
  const std::uint8_t* data_;
  std::size_t bytes_;
  std::size_t at_ = 0;
};

}  // namespace

Bytes encodePng(const cv::Mat& rgb, const cv::Mat& mask) {
  const cv::Mat alpha = mask.empty() ? cv::Mat(rgb.size(), CV_8UC1, cv::Scalar(255)) : mask;
  cv::Mat bgra(rgb.size(), CV_8UC4);
  const cv::Mat sources[] = {rgb, alpha};
  cv::mixChannels(sources, 2, &bgra, 1, kBgraToRgbMask, 4);
  Bytes png;
  if (!cv::imencode(".png", bgra, png)) throw core::Error("cannot encode the texture as PNG");
  return png;
}

void decodePng(const void* data, std::size_t bytes, cv::Mat& rgb, cv::Mat& mask) {
  cv::Mat bgra;
  try {
    // imdecode only reads its input; the const_cast is for cv::Mat's constructor.
    const cv::Mat encoded(1, static_cast<int>(bytes), CV_8UC1, const_cast<void*>(data));
    bgra = cv::imdecode(encoded, cv::IMREAD_UNCHANGED);
  } catch (const cv::Exception& e) {
    throw core::Error(std::string("undecodable PNG: ") + e.what());
  }
  if (bgra.empty() || bgra.type() != CV_8UC4) throw core::Error("the PNG is not 8-bit RGBA");
  rgb.create(bgra.size(), CV_8UC3);
  mask.create(bgra.size(), CV_8UC1);
  cv::Mat targets[] = {rgb, mask};
  cv::mixChannels(&bgra, 1, targets, 2, kBgraToRgbMask, 4);
}

Bytes encodeFloats(const std::vector<float>& values) {
  Bytes out(values.size() * sizeof(float));
  if (!values.empty()) std::memcpy(out.data(), values.data(), out.size());
  return out;
}

std::vector<float> decodeFloats(const void* data, std::size_t bytes) {
  if (bytes % sizeof(float) != 0) throw core::Error("float array of odd length");
  std::vector<float> values(bytes / sizeof(float));
  Reader(data, bytes).copyTo(values.data(), bytes);
  return values;
}

Bytes encodeKeypoints(const std::vector<cv::KeyPoint>& keypoints) {
  Bytes out;
  if (keypoints.empty()) return out;
  out.reserve(1 + sizeof(std::uint32_t) + keypoints.size() * kKeypointBytes);
  put(out, kKeypointFormat);
  put(out, static_cast<std::uint32_t>(keypoints.size()));
  for (const cv::KeyPoint& k : keypoints) {
    put(out, k.pt.x);
    put(out, k.pt.y);
    put(out, k.size);
    put(out, k.angle);
    put(out, k.response);
    put(out, static_cast<std::int32_t>(k.octave));
    put(out, static_cast<std::int32_t>(k.class_id));
  }
  return out;
}

std::vector<cv::KeyPoint> decodeKeypoints(const void* data, std::size_t bytes) {
  std::vector<cv::KeyPoint> keypoints;
  if (bytes == 0) return keypoints;
  Reader in(data, bytes);
  if (in.get<std::uint8_t>() != kKeypointFormat) throw core::Error("unknown keypoint format");
  const auto count = in.get<std::uint32_t>();
  if (in.remaining() != count * kKeypointBytes) throw core::Error("keypoint blob size mismatch");
  keypoints.resize(count);
  for (cv::KeyPoint& k : keypoints) {
    k.pt.x = in.get<float>();
    k.pt.y = in.get<float>();
    k.size = in.get<float>();
    k.angle = in.get<float>();
    k.response = in.get<float>();
    k.octave = in.get<std::int32_t>();
    k.class_id = in.get<std::int32_t>();
  }
  return keypoints;
}

Bytes encodeDescriptors(const cv::Mat& descriptors) {
  Bytes out;
  if (descriptors.empty()) return out;
  const cv::Mat dense = descriptors.isContinuous() ? descriptors : descriptors.clone();
  const std::size_t data_bytes = dense.total() * dense.elemSize();
  out.reserve(kDescriptorHeaderBytes + data_bytes);
  put(out, static_cast<std::int32_t>(dense.rows));
  put(out, static_cast<std::int32_t>(dense.cols));
  put(out, static_cast<std::int32_t>(dense.type()));
  const std::size_t at = out.size();
  out.resize(at + data_bytes);
  std::memcpy(out.data() + at, dense.data, data_bytes);
  return out;
}

cv::Mat decodeDescriptors(const void* data, std::size_t bytes) {
  if (bytes == 0) return {};
  Reader in(data, bytes);
  const auto rows = in.get<std::int32_t>();
  const auto cols = in.get<std::int32_t>();
  const auto type = in.get<std::int32_t>();
  if (rows <= 0 || cols <= 0 || type < 0 || CV_MAT_DEPTH(type) > CV_16F || CV_MAT_CN(type) > 4) {
    throw core::Error("bad descriptor header");
  }
  const std::size_t data_bytes = static_cast<std::size_t>(rows) * static_cast<std::size_t>(cols) *
                                 static_cast<std::size_t>(CV_ELEM_SIZE(type));
  if (in.remaining() != data_bytes) throw core::Error("descriptor blob size mismatch");
  cv::Mat descriptors(rows, cols, type);
  in.copyTo(descriptors.data, data_bytes);
  return descriptors;
}

}  // namespace tessera::db::internal
