// Colour conversions of the V4L2 driver against known colours.
#include <random>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>

#include "drivers/v4l2_fake_device.h"
#include "tessera/drivers/v4l2/pixel_conversion.h"

namespace tessera::drivers::v4l2 {
namespace {

// Vertical stripes of known colours, each 16 pixels wide (whole JPEG chroma blocks, even
// YUYV pairs), so that every stripe's centre keeps its colour through any of the formats.
const std::vector<cv::Vec3b> kColours = {{255, 0, 0},     {0, 255, 0}, {0, 0, 255},
                                         {255, 255, 255}, {0, 0, 0},   {200, 120, 40}};
constexpr int kStripe = 16, kStripeHeight = 16;

cv::Mat stripes() {
  cv::Mat rgb(kStripeHeight, kStripe * static_cast<int>(kColours.size()), CV_8UC3);
  for (int u = 0; u < rgb.cols; ++u)
    rgb.col(u).setTo(
        cv::Scalar(kColours[u / kStripe][0], kColours[u / kStripe][1], kColours[u / kStripe][2]));
  return rgb;
}

PixelFormat formatOf(std::uint32_t fourcc, int width, int height, int bytes_per_pixel) {
  PixelFormat format;
  format.fourcc = fourcc;
  format.width = width;
  format.height = height;
  format.bytes_per_line = static_cast<std::uint32_t>(width * bytes_per_pixel);
  format.size_image = format.bytes_per_line * static_cast<std::uint32_t>(height);
  return format;
}

cv::Mat asMat(const std::vector<std::uint8_t>& bytes) {
  return cv::Mat(1, static_cast<int>(bytes.size()), CV_8UC1,
                 const_cast<std::uint8_t*>(bytes.data()))
      .clone();
}

// Every stripe's centre pixel is its colour within `tolerance` per channel.
void expectStripes(const cv::Mat& rgb, int tolerance) {
  ASSERT_EQ(rgb.type(), CV_8UC3);
  ASSERT_EQ(rgb.cols, kStripe * static_cast<int>(kColours.size()));
  for (std::size_t i = 0; i < kColours.size(); ++i) {
    const cv::Vec3b got =
        rgb.at<cv::Vec3b>(kStripeHeight / 2, static_cast<int>(i) * kStripe + kStripe / 2);
    for (int c = 0; c < 3; ++c) {
      EXPECT_NEAR(got[c], kColours[i][c], tolerance)
          << "stripe " << i << " channel " << c << " (R, G, B order)";
    }
  }
}

TEST(Conversion, YuyvGivesKnownColoursInRgbOrder) {
  const cv::Mat rgb = stripes();
  const auto bytes = fake::yuyvBytes(rgb);
  std::string problem;
  const cv::Mat out =
      colourToRgb(formatOf(V4L2_PIX_FMT_YUYV, rgb.cols, rgb.rows, 2), asMat(bytes), problem);
  EXPECT_TRUE(problem.empty()) << problem;
  expectStripes(out, 3);  // limited-range 8-bit YCbCr loses up to ~2 levels
}

TEST(Conversion, YuyvHonoursAPaddedRowStride) {
  const cv::Mat rgb = stripes();
  const auto packed = fake::yuyvBytes(rgb);
  const std::size_t row = static_cast<std::size_t>(rgb.cols) * 2, stride = row + 32;
  std::vector<std::uint8_t> padded(stride * static_cast<std::size_t>(rgb.rows), 0x55);
  for (int v = 0; v < rgb.rows; ++v) {
    std::copy_n(packed.begin() + static_cast<std::ptrdiff_t>(row * static_cast<std::size_t>(v)),
                row,
                padded.begin() + static_cast<std::ptrdiff_t>(stride * static_cast<std::size_t>(v)));
  }
  PixelFormat format = formatOf(V4L2_PIX_FMT_YUYV, rgb.cols, rgb.rows, 2);
  format.bytes_per_line = static_cast<std::uint32_t>(stride);
  std::string problem;
  expectStripes(colourToRgb(format, asMat(padded), problem), 3);
}

TEST(Conversion, Rgb24IsTakenAsIs) {
  cv::Mat rgb(9, 14, CV_8UC3);
  cv::RNG rng(7);
  rng.fill(rgb, cv::RNG::UNIFORM, 0, 256);
  std::string problem;
  const cv::Mat out = colourToRgb(formatOf(V4L2_PIX_FMT_RGB24, rgb.cols, rgb.rows, 3),
                                  asMat(fake::rgb24Bytes(rgb)), problem);
  ASSERT_EQ(out.size(), rgb.size());
  EXPECT_EQ(cv::norm(out, rgb, cv::NORM_INF), 0.0);
}

TEST(Conversion, MjpegGivesKnownColoursWithinJpegTolerance) {
  const cv::Mat rgb = stripes();
  PixelFormat format = formatOf(V4L2_PIX_FMT_MJPEG, rgb.cols, rgb.rows, 2);
  format.bytes_per_line = 0;
  auto bytes = fake::mjpegBytes(rgb, 95);
  bytes.resize(bytes.size() + 100, 0);  // UVC cameras pad frames after the end marker
  std::string problem;
  const cv::Mat out = colourToRgb(format, asMat(bytes), problem);
  EXPECT_TRUE(problem.empty()) << problem;
  expectStripes(out, 12);
}

TEST(Conversion, CorruptOrTruncatedJpegIsRejected) {
  const cv::Mat rgb = stripes();
  PixelFormat format = formatOf(V4L2_PIX_FMT_MJPEG, rgb.cols, rgb.rows, 2);
  const auto good = fake::mjpegBytes(rgb, 90);
  std::vector<std::uint8_t> truncated(good.begin(),
                                      good.begin() + static_cast<std::ptrdiff_t>(good.size() / 2));
  std::vector<std::uint8_t> garbage(good.size());
  std::mt19937 rng(3);
  for (auto& byte : garbage) byte = static_cast<std::uint8_t>(rng());
  // Start and end markers intact, the tables behind the start marker overwritten.
  std::vector<std::uint8_t> bad_header = good;
  std::fill(bad_header.begin() + 2, bad_header.begin() + 64, std::uint8_t{0x5a});
  for (const auto* bytes : {&truncated, &garbage, &bad_header}) {
    std::string problem;
    EXPECT_TRUE(colourToRgb(format, asMat(*bytes), problem).empty());
    EXPECT_NE(problem.find("JPEG"), std::string::npos) << problem;
  }
  // A whole JPEG of another size is no frame of this stream either.
  format.width /= 2;
  std::string problem;
  EXPECT_TRUE(colourToRgb(format, asMat(good), problem).empty());
  EXPECT_NE(problem.find("JPEG is 96x16"), std::string::npos) << problem;
}

}  // namespace
}  // namespace tessera::drivers::v4l2
