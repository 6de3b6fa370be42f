// sensor_msgs/Image encodings and the compressed transports' sensor_msgs/CompressedImage to
// and from tessera's images.
#include <cstring>
#include <functional>
#include <random>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include <opencv2/imgcodecs.hpp>

#include "tessera/core/error.h"
#include "tessera/drivers/ros1/compressed_image.h"
#include "tessera/drivers/ros1/ros_image.h"

namespace tessera::drivers::ros1 {
namespace {

cv::Mat randomDepth(int width, int height, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> depth(0, 65535);
  cv::Mat mm(height, width, CV_16UC1);
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      // Every fifth pixel has no depth.
      mm.at<std::uint16_t>(y, x) = (x + y) % 5 == 0 ? 0 : static_cast<std::uint16_t>(depth(rng));
    }
  }
  return mm;
}

// Smooth colour gradients: what demosaicking and 4:2:2 chroma can be judged on.
cv::Mat smoothColour(int width, int height) {
  cv::Mat rgb(height, width, CV_8UC3);
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      rgb.at<cv::Vec3b>(y, x) = cv::Vec3b(static_cast<std::uint8_t>(40 + x * 160 / width),
                                          static_cast<std::uint8_t>(200 - y * 150 / height),
                                          static_cast<std::uint8_t>(90 + (x + y) % 40));
    }
  }
  return rgb;
}

double meanAbsoluteError(const cv::Mat& a, const cv::Mat& b) {
  cv::Mat difference;
  cv::absdiff(a, b, difference);
  const cv::Scalar mean = cv::mean(difference);
  return (mean[0] + mean[1] + mean[2]) / 3.0;
}

TEST(Ros1Image, DepthRoundTripsBitExactIn16UC1And32FC1) {
  const cv::Mat depth = randomDepth(64, 48, 7);
  for (const char* encoding : {"16UC1", "32FC1"}) {
    const sensor_msgs::Image image = imageFromDepth(depth, encoding);
    EXPECT_EQ(image.encoding, encoding);
    const cv::Mat back = depthFromImage(image);
    ASSERT_EQ(back.type(), CV_16UC1);
    EXPECT_EQ(cv::norm(back, depth, cv::NORM_INF), 0.0) << encoding;
  }
}

TEST(Ros1Image, MetricDepthLosesWhatIsNotADistance) {
  sensor_msgs::Image image = imageFromDepth(cv::Mat(1, 5, CV_16UC1, cv::Scalar(0)), "32FC1");
  const float metres[5] = {1.2344f, std::numeric_limits<float>::quiet_NaN(), -1.0f,
                           std::numeric_limits<float>::infinity(), 70.0f};
  std::memcpy(image.data.data(), metres, sizeof(metres));
  const cv::Mat mm = depthFromImage(image);
  EXPECT_EQ(mm.at<std::uint16_t>(0, 0), 1234);
  for (int x = 1; x < 5; ++x) EXPECT_EQ(mm.at<std::uint16_t>(0, x), 0) << x;
}

TEST(Ros1Image, BigEndianDepthIsSwapped) {
  const cv::Mat depth = randomDepth(8, 4, 3);
  sensor_msgs::Image image = imageFromDepth(depth, "16UC1");
  for (std::size_t i = 0; i + 1 < image.data.size(); i += 2)
    std::swap(image.data[i], image.data[i + 1]);
  image.is_bigendian = 1;
  EXPECT_EQ(cv::norm(depthFromImage(image), depth, cv::NORM_INF), 0.0);
}

TEST(Ros1Image, EveryColourEncodingDecodesToTheImage) {
  const cv::Mat rgb = smoothColour(96, 64);
  for (const char* encoding : {"rgb8", "bgr8"}) {
    EXPECT_EQ(cv::norm(colourFromImage(imageFromColour(rgb, encoding)), rgb, cv::NORM_INF), 0.0)
        << encoding;
  }
  // A mosaic keeps one channel in three and 4:2:2 half the chroma: on a smooth image the
  // decoded colour stays within a few levels. The wrong Bayer layout would swap red and blue
  // (an error of about 50 levels here).
  for (const char* encoding : {"bayer_rggb8", "bayer_bggr8", "bayer_gbrg8", "bayer_grbg8"}) {
    const cv::Mat decoded = colourFromImage(imageFromColour(rgb, encoding));
    const cv::Rect inner(2, 2, rgb.cols - 4, rgb.rows - 4);  // demosaicking guesses at borders
    EXPECT_LT(meanAbsoluteError(decoded(inner), rgb(inner)), 4.0) << encoding;
  }
  for (const char* encoding : {"yuv422", "yuv422_yuy2"}) {
    EXPECT_LT(meanAbsoluteError(colourFromImage(imageFromColour(rgb, encoding)), rgb), 3.0)
        << encoding;
  }
}

TEST(Ros1Image, FourChannelAndMonoColourAreRead) {
  const cv::Mat rgb = smoothColour(16, 8);
  cv::Mat rgba, bgra, grey;
  cv::cvtColor(rgb, rgba, cv::COLOR_RGB2RGBA);
  cv::cvtColor(rgb, bgra, cv::COLOR_RGB2BGRA);
  cv::cvtColor(rgb, grey, cv::COLOR_RGB2GRAY);
  sensor_msgs::Image image = imageFromColour(rgb, "rgb8");
  const auto as = [&](const cv::Mat& pixels, const char* encoding) {
    sensor_msgs::Image message = image;
    message.encoding = encoding;
    message.step = static_cast<std::uint32_t>(pixels.cols * pixels.elemSize());
    message.data.assign(pixels.datastart, pixels.dataend);
    return colourFromImage(message);
  };
  EXPECT_EQ(cv::norm(as(rgba, "rgba8"), rgb, cv::NORM_INF), 0.0);
  EXPECT_EQ(cv::norm(as(bgra, "bgra8"), rgb, cv::NORM_INF), 0.0);
  const cv::Mat from_grey = as(grey, "mono8");
  std::vector<cv::Mat> channels;
  cv::split(from_grey, channels);
  EXPECT_EQ(cv::norm(channels[0], grey, cv::NORM_INF), 0.0);
}

TEST(Ros1Image, UnknownEncodingsAndShortDataAreNamed) {
  sensor_msgs::Image image = imageFromColour(smoothColour(8, 4), "rgb8");
  image.encoding = "jpeg";
  try {
    colourFromImage(image);
    FAIL() << "an unknown encoding was read";
  } catch (const core::SourceError& e) {
    EXPECT_NE(std::string(e.what()).find("'jpeg'"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("bayer_grbg8"), std::string::npos) << e.what();
  }
  EXPECT_THROW(depthFromImage(image), core::SourceError);
  sensor_msgs::Image short_depth = imageFromDepth(randomDepth(8, 4, 1), "16UC1");
  short_depth.data.resize(10);
  EXPECT_THROW(depthFromImage(short_depth), core::SourceError);
}

TEST(Ros1CompressedImage, DepthRoundTripsBitExactThroughCompressedDepth) {
  const cv::Mat depth = randomDepth(64, 48, 11);
  const sensor_msgs::CompressedImage message = compressedFromDepth(depth);
  EXPECT_EQ(message.format, "16UC1; compressedDepth png");
  const cv::Mat back = depthFromCompressed(message);
  ASSERT_EQ(back.type(), CV_16UC1);
  EXPECT_EQ(cv::norm(back, depth, cv::NORM_INF), 0.0);
}

// 32FC1 compressedDepth as the transport writes it (its defaults: quantisation 100, 10 m):
// v = a / d + b, a = 100 * 101, b = 1 - a / 10; v = 0 where there is no depth.
TEST(Ros1CompressedImage, MetricCompressedDepthIsQuantisedInverseDepth) {
  const float a = 100.0F * 101.0F, b = 1.0F - a / 10.0F;
  const double metres[5] = {0.0, 0.5, 1.234, 3.0, 9.5};
  cv::Mat v(1, 5, CV_16UC1);
  for (int i = 0; i < 5; ++i) {
    v.at<std::uint16_t>(0, i) =
        metres[i] == 0.0 ? 0 : static_cast<std::uint16_t>(std::lround(a / metres[i] + b));
  }
  sensor_msgs::CompressedImage message;
  message.format = "32FC1; compressedDepth png";
  message.data.assign(12, 0);
  std::memcpy(message.data.data() + 4, &a, 4);
  std::memcpy(message.data.data() + 8, &b, 4);
  std::vector<std::uint8_t> png;
  cv::imencode(".png", v, png);
  message.data.insert(message.data.end(), png.begin(), png.end());
  const cv::Mat mm = depthFromCompressed(message);
  EXPECT_EQ(mm.at<std::uint16_t>(0, 0), 0);
  for (int i = 1; i < 5; ++i) {
    // Half a quantisation step, d^2 / a, plus the millimetre's rounding.
    const double bound = 1000.0 * 0.5 * metres[i] * metres[i] / a + 0.5;
    EXPECT_NEAR(mm.at<std::uint16_t>(0, i), 1000.0 * metres[i], bound) << metres[i];
  }
}

TEST(Ros1CompressedImage, ColourAsPngIsExactAndAsJpegClose) {
  const cv::Mat rgb = smoothColour(64, 48);
  const sensor_msgs::CompressedImage png = compressedFromColour(rgb, "png");
  EXPECT_EQ(png.format, "rgb8; png compressed bgr8");
  EXPECT_EQ(cv::norm(colourFromCompressed(png), rgb, cv::NORM_INF), 0.0);
  const cv::Mat from_jpeg = colourFromCompressed(compressedFromColour(rgb, "jpeg"));
  ASSERT_EQ(from_jpeg.size(), rgb.size());
  EXPECT_LT(meanAbsoluteError(from_jpeg, rgb), 3.0);  // R and B not swapped: that would be 40+
  EXPECT_THROW(compressedFromColour(rgb, "bmp"), core::ConfigError);
}

// What `read` throws as core::SourceError; empty when it throws nothing.
std::string sourceErrorOf(const std::function<void()>& read) {
  try {
    read();
  } catch (const core::SourceError& e) {
    return e.what();
  }
  return "";
}

TEST(Ros1CompressedImage, WhatCannotBeReadIsNamed) {
  sensor_msgs::CompressedImage depth = compressedFromDepth(randomDepth(16, 8, 3));
  sensor_msgs::CompressedImage jpeg_depth = depth;
  jpeg_depth.format = "16UC1; jpeg compressed mono16";
  EXPECT_NE(sourceErrorOf([&] { depthFromCompressed(jpeg_depth); }).find("not compressedDepth"),
            std::string::npos);
  sensor_msgs::CompressedImage wrong_encoding = depth;
  wrong_encoding.format = "8UC1; compressedDepth png";
  EXPECT_NE(sourceErrorOf([&] { depthFromCompressed(wrong_encoding); }).find("'8UC1'"),
            std::string::npos);
  sensor_msgs::CompressedImage header_only = depth;
  header_only.data.resize(12);
  EXPECT_NE(sourceErrorOf([&] { depthFromCompressed(header_only); }).find("RVL"),
            std::string::npos);
  sensor_msgs::CompressedImage cut = depth;
  cut.data.resize(40);
  EXPECT_NE(sourceErrorOf([&] { depthFromCompressed(cut); }).find("cut short"), std::string::npos);
  sensor_msgs::CompressedImage colour = compressedFromColour(smoothColour(16, 8), "png");
  colour.data.resize(30);
  EXPECT_NE(sourceErrorOf([&] { colourFromCompressed(colour); }).find("cannot be decoded"),
            std::string::npos);
}

// image_transport's PNG keeps a Bayer image as its mosaic: it is demosaicked as a raw one is.
TEST(Ros1CompressedImage, ABayerMosaicAsPngIsDemosaicked) {
  const cv::Mat rgb = smoothColour(96, 64);
  const sensor_msgs::Image raw = imageFromColour(rgb, "bayer_grbg8");
  const cv::Mat mosaic(static_cast<int>(raw.height), static_cast<int>(raw.width), CV_8UC1,
                       const_cast<std::uint8_t*>(raw.data.data()), raw.step);
  sensor_msgs::CompressedImage png;
  png.format = "bayer_grbg8; png compressed ";
  cv::imencode(".png", mosaic, png.data);
  EXPECT_EQ(cv::norm(colourFromCompressed(png), colourFromImage(raw), cv::NORM_INF), 0.0);
}

// A corrupt or hostile header must not make the decoder allocate what it claims.
TEST(Ros1CompressedImage, AHugeDeclaredSizeIsRefusedBeforeDecoding) {
  const auto putBigEndian = [](std::vector<std::uint8_t>& data, std::size_t at, std::uint32_t v,
                               int bytes) {
    for (int i = bytes - 1; i >= 0; --i, v >>= 8) data[at + static_cast<std::size_t>(i)] = v & 0xFF;
  };
  sensor_msgs::CompressedImage depth = compressedFromDepth(randomDepth(16, 8, 3));
  putBigEndian(depth.data, 12 + 16, 60000, 4);  // the PNG's IHDR width and height
  putBigEndian(depth.data, 12 + 20, 60000, 4);
  EXPECT_NE(sourceErrorOf([&] { depthFromCompressed(depth); }).find("declares 60000 x 60000"),
            std::string::npos);

  sensor_msgs::CompressedImage jpeg = compressedFromColour(smoothColour(16, 8), "jpeg");
  std::size_t sof = 2;
  while (sof + 1 < jpeg.data.size() && !(jpeg.data[sof] == 0xFF && jpeg.data[sof + 1] == 0xC0))
    ++sof;
  ASSERT_LT(sof + 9, jpeg.data.size()) << "no baseline start-of-frame segment";
  putBigEndian(jpeg.data, sof + 5, 40000, 2);  // height, then width
  putBigEndian(jpeg.data, sof + 7, 30000, 2);
  EXPECT_NE(sourceErrorOf([&] { colourFromCompressed(jpeg); }).find("declares 30000 x 40000"),
            std::string::npos);

  sensor_msgs::CompressedImage bmp;
  bmp.format = "rgb8; bmp compressed bgr8";
  bmp.data = {'B', 'M', 0, 0, 0, 0, 0, 0};
  EXPECT_NE(sourceErrorOf([&] { colourFromCompressed(bmp); }).find("not a PNG or JPEG"),
            std::string::npos);
}

TEST(Ros1Image, CameraInfoCarriesTheIntrinsics) {
  core::Intrinsics k;
  k.width = 640, k.height = 480, k.fx = 517.3, k.fy = 516.5, k.cx = 318.6, k.cy = 255.3;
  const core::Intrinsics back = intrinsicsFromCameraInfo(cameraInfoFromIntrinsics(k));
  EXPECT_EQ(back.width, 640);
  EXPECT_EQ(back.height, 480);
  EXPECT_DOUBLE_EQ(back.fx, k.fx);
  EXPECT_DOUBLE_EQ(back.fy, k.fy);
  EXPECT_DOUBLE_EQ(back.cx, k.cx);
  EXPECT_DOUBLE_EQ(back.cy, k.cy);
  EXPECT_FALSE(intrinsicsFromCameraInfo(sensor_msgs::CameraInfo()).valid());
}

}  // namespace
}  // namespace tessera::drivers::ros1
