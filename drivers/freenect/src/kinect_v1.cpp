#include "tessera/drivers/freenect/kinect_v1.h"

#include <array>
#include <cmath>

namespace tessera::drivers::freenect {

namespace {

constexpr int kRawValues = 2048;  // FREENECT_DEPTH_RAW_MAX_VALUE
constexpr double kMaxDepthMm = 10000.0;

std::array<std::uint16_t, kRawValues> makeTable() {
  std::array<std::uint16_t, kRawValues> table{};
  for (int raw = 0; raw < kRawValues; ++raw) {
    if (raw == kRawNoDepth) continue;
    // Burrus (2011), see the header.
    const double inverse_m = raw * -0.0030711016 + 3.3309495161;
    if (inverse_m <= 0.0) continue;  // raw >= 1085: beyond the model's range
    const double mm = 1000.0 / inverse_m;
    if (mm <= kMaxDepthMm)
      table[static_cast<std::size_t>(raw)] = static_cast<std::uint16_t>(std::lround(mm));
  }
  return table;
}

const std::array<std::uint16_t, kRawValues>& table() {
  static const std::array<std::uint16_t, kRawValues> instance = makeTable();
  return instance;
}

}  // namespace

std::uint16_t disparityToMm(std::uint16_t raw) {
  return raw < kRawValues ? table()[raw] : std::uint16_t{0};
}

cv::Mat disparityImageToMm(const cv::Mat& raw) {
  CV_Assert(raw.type() == CV_16UC1);
  cv::Mat mm(raw.size(), CV_16UC1);
  const auto& lut = table();
  for (int y = 0; y < raw.rows; ++y) {
    const auto* in = raw.ptr<std::uint16_t>(y);
    auto* out = mm.ptr<std::uint16_t>(y);
    for (int x = 0; x < raw.cols; ++x) out[x] = in[x] < kRawValues ? lut[in[x]] : std::uint16_t{0};
  }
  return mm;
}

core::Intrinsics typicalDepthIntrinsics() {
  const double f = 120.0 / (2.0 * 0.1042);
  return {640, 480, f, f, 319.5, 239.5};
}

core::Intrinsics typicalColourIntrinsics() { return {640, 480, 525.0, 525.0, 319.5, 239.5}; }

core::ColourCamera typicalColourCamera() {
  core::ColourCamera camera;
  camera.intrinsics = typicalColourIntrinsics();
  camera.T_RGB_D = core::Isometry::Identity();
  camera.T_RGB_D.translation() = Eigen::Vector3d(0.025, 0.0, 0.0);
  return camera;
}

}  // namespace tessera::drivers::freenect
