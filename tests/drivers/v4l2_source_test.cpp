// V4l2Source with a depth and a colour node: timestamp pairing, failures of the colour node.
#include <cmath>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>

#include "drivers/v4l2_fake_device.h"
#include "tessera/core/error.h"
#include "tessera/drivers/v4l2/v4l2_source.h"

namespace tessera::drivers::v4l2 {
namespace {

using fake::FakeCamera;
using fake::FakeEnding;

constexpr int kSourceWidth = 8, kSourceHeight = 6;
constexpr std::int64_t kStartNs = 5'000'000'000;
const std::string kUri = "v4l2:///dev/video0?depth=/dev/video2";

// V4L2 buffer timestamps are whole microseconds (a struct timeval); so are the scripted ones.
std::int64_t microseconds(double us) { return std::llround(us) * 1000; }

std::shared_ptr<FakeCamera> camera(const std::string& path, std::uint32_t fourcc) {
  auto fake = std::make_shared<FakeCamera>();
  fake->path = path;
  fake->formats = {fourcc};
  fake->width = kSourceWidth;
  fake->height = kSourceHeight;
  return fake;
}

// Depth frame i holds the value 100 + i everywhere, colour frame j the red level j: a delivered
// frame tells which two frames were paired.
std::shared_ptr<FakeCamera> depthStream(int count, double period_ms) {
  auto depth = camera("/dev/video2", V4L2_PIX_FMT_Z16);
  for (int i = 0; i < count; ++i) {
    const cv::Mat image(kSourceHeight, kSourceWidth, CV_16UC1, cv::Scalar(100 + i));
    depth->frames.push_back(
        {kStartNs + microseconds(i * period_ms * 1e3), fake::z16Bytes(image), false});
  }
  depth->ending = FakeEnding::kDisappearOnDequeue;
  return depth;
}

std::shared_ptr<FakeCamera> colourStream(int count, double period_ms, double offset_ms) {
  auto colour = camera("/dev/video0", V4L2_PIX_FMT_RGB24);
  for (int j = 0; j < count; ++j) {
    const cv::Mat image(kSourceHeight, kSourceWidth, CV_8UC3, cv::Scalar(j, 50, 60));
    colour->frames.push_back({kStartNs + microseconds((offset_ms + j * period_ms) * 1e3),
                              fake::rgb24Bytes(image), false});
  }
  return colour;
}

V4l2Options options(const std::vector<std::shared_ptr<FakeCamera>>& cameras) {
  V4l2Options result;
  core::Intrinsics k;
  k.fx = k.fy = 10.0, k.cx = 3.5, k.cy = 2.5;
  result.intrinsics = k;
  result.make_device = fake::fakeFactory(cameras);
  result.pair_wait_ms = 20;
  return result;
}

// The plain rule: the colour frame nearest in time, if within the tolerance.
int nearestColour(std::int64_t depth_ns, const FakeCamera& colour, double tolerance_ms) {
  int best = -1;
  double best_gap = 0.0;
  for (std::size_t j = 0; j < colour.frames.size(); ++j) {
    const double gap =
        std::abs(static_cast<double>(colour.frames[j].timestamp_ns - depth_ns)) * 1e-6;
    if (best < 0 || gap < best_gap) best = static_cast<int>(j), best_gap = gap;
  }
  return best_gap <= tolerance_ms ? best : -1;
}

TEST(Pairing, EachDepthFrameGetsTheNearestColourFrameWithinTolerance) {
  struct Rates {
    double colour_period_ms, colour_offset_ms;
    int expected_unpaired;
  };
  // 30 Hz depth with 25 Hz colour 5 ms late (some depth frames fall between colour frames),
  // and with 60 Hz colour 3 ms early (every depth frame has a partner, every other colour frame
  // is dropped).
  for (const Rates rates : {Rates{40.0, 5.0, 2}, Rates{1000.0 / 60.0, -3.0, 0}}) {
    SCOPED_TRACE(rates.colour_period_ms);
    const auto depth = depthStream(12, 1000.0 / 30.0);
    const auto colour = colourStream(40, rates.colour_period_ms, rates.colour_offset_ms);
    V4l2Source source(kUri, options({depth, colour}));
    ASSERT_TRUE(source.hasColour());
    int unpaired = 0;
    for (std::size_t i = 0; i < depth->frames.size(); ++i) {
      const core::ReadResult result = source.read();
      const int expected = nearestColour(depth->frames[i].timestamp_ns, *colour, 16.7);
      if (expected < 0) {
        ++unpaired;
        EXPECT_EQ(result.status, core::ReadStatus::kBadFrame) << "depth frame " << i;
        EXPECT_NE(result.problem.find("no colour frame within 16.7 ms"), std::string::npos)
            << result.problem;
        continue;
      }
      ASSERT_EQ(result.status, core::ReadStatus::kFrame) << "depth " << i << ": " << result.problem;
      EXPECT_EQ(result.frame.depth_mm.at<std::uint16_t>(0, 0), 100 + i);
      EXPECT_EQ(result.frame.rgb.at<cv::Vec3b>(0, 0)[0], expected) << "depth frame " << i;
      EXPECT_EQ(result.frame.rgb.at<cv::Vec3b>(0, 0)[1], 50);  // R, G, B order
      EXPECT_EQ(result.frame.timestamp_ns, depth->frames[i].timestamp_ns);
      EXPECT_FALSE(result.frame.colour_camera.has_value());  // no calibration: registered
    }
    EXPECT_EQ(unpaired, rates.expected_unpaired);
    const core::ReadResult end = source.read();
    EXPECT_EQ(end.status, core::ReadStatus::kEndOfData);
    EXPECT_NE(end.problem.find("/dev/video2"), std::string::npos) << end.problem;
  }
}

TEST(Pairing, FourDepthFramesPairAsWorkedOutByHand) {
  // 25 Hz colour 5 ms late: depth 0 ms -> colour 5 ms (0), 33.3 -> 45 (1), 66.7 -> none
  // (45 and 85 are 21.7 and 18.3 ms away), 100 -> 85 (2).
  const auto depth = depthStream(4, 1000.0 / 30.0);
  const auto colour = colourStream(6, 40.0, 5.0);
  V4l2Source source(kUri, options({depth, colour}));
  const int expected[] = {0, 1, -1, 2};
  for (const int j : expected) {
    const core::ReadResult result = source.read();
    if (j < 0) {
      EXPECT_EQ(result.status, core::ReadStatus::kBadFrame);
      EXPECT_NE(result.problem.find("nearest 18.3 ms away"), std::string::npos) << result.problem;
    } else {
      ASSERT_EQ(result.status, core::ReadStatus::kFrame) << result.problem;
      EXPECT_EQ(result.frame.rgb.at<cv::Vec3b>(0, 0)[0], j);
    }
  }
}

TEST(Pairing, ColourNodeThatDisappearsEndsTheStreamNamingIt) {
  const auto depth = depthStream(10, 1000.0 / 30.0);
  const auto colour = colourStream(3, 1000.0 / 30.0, 1.0);
  colour->ending = FakeEnding::kDisappearOnDequeue;
  V4l2Source source(kUri, options({depth, colour}));
  for (int i = 0; i < 3; ++i) EXPECT_EQ(source.read().status, core::ReadStatus::kFrame);
  const core::ReadResult end = source.read();
  EXPECT_EQ(end.status, core::ReadStatus::kEndOfData);
  EXPECT_NE(end.problem.find("/dev/video0: the colour device disappeared"), std::string::npos)
      << end.problem;
}

TEST(Pairing, CorruptJpegColourIsABadFrameAndTheNextPairIsFine) {
  const auto depth = depthStream(3, 1000.0 / 30.0);
  auto colour = camera("/dev/video0", V4L2_PIX_FMT_MJPEG);
  for (int j = 0; j < 4; ++j) {
    const cv::Mat image(kSourceHeight, kSourceWidth, CV_8UC3, cv::Scalar(200, 40, 40));
    colour->frames.push_back(
        {kStartNs + microseconds(j * 1e6 / 30.0), fake::mjpegBytes(image, 95), false});
  }
  colour->frames[1].bytes.resize(colour->frames[1].bytes.size() * 2 / 3);  // cut mid-frame
  V4l2Source source(kUri, options({depth, colour}));
  EXPECT_EQ(source.read().status, core::ReadStatus::kFrame);
  const core::ReadResult bad = source.read();
  EXPECT_EQ(bad.status, core::ReadStatus::kBadFrame);
  EXPECT_NE(bad.problem.find("/dev/video0: corrupt or truncated JPEG"), std::string::npos)
      << bad.problem;
  const core::ReadResult next = source.read();
  ASSERT_EQ(next.status, core::ReadStatus::kFrame) << next.problem;
  EXPECT_NEAR(next.frame.rgb.at<cv::Vec3b>(3, 4)[0], 200, 12);
}

TEST(Source, RegisteredColourMustHaveTheDepthSize) {
  const auto depth = depthStream(1, 33.3);
  auto colour = camera("/dev/video0", V4L2_PIX_FMT_YUYV);
  colour->width = 2 * kSourceWidth;  // a colour node that is not registered to depth
  try {
    V4l2Source source(kUri, options({depth, colour}));
    FAIL() << "colour at another size than depth was accepted without calibration";
  } catch (const core::SourceError& e) {
    EXPECT_NE(std::string(e.what()).find("add calibration=FILE.yaml"), std::string::npos)
        << e.what();
  }
  EXPECT_EQ(depth->closes, 1);  // the depth node opened first is released again
}

TEST(Source, WithoutIntrinsicsOrProfileIsAConfigError) {
  V4l2Options no_intrinsics = options({depthStream(1, 33.3)});
  no_intrinsics.intrinsics.reset();
  EXPECT_THROW(V4l2Source("v4l2://?depth=/dev/video2", no_intrinsics), core::ConfigError);
}

TEST(Source, MissingNodeIsASourceErrorNamingIt) {
  try {
    V4l2Source source("v4l2://?depth=/dev/video9", options({depthStream(1, 33.3)}));
    FAIL();
  } catch (const core::SourceError& e) {
    EXPECT_NE(std::string(e.what()).find("/dev/video9: cannot open the depth node"),
              std::string::npos)
        << e.what();
  }
}

// The real backend (libv4l2) on nodes that are no camera: the message names the node.
TEST(Source, SystemBackendNamesANodeThatIsNoCamera) {
  V4l2Options system = options({});
  system.make_device = nullptr;
  const std::pair<std::string, std::string> cases[] = {
      {"v4l2://?depth=/dev/tessera-no-such-node", "/dev/tessera-no-such-node: cannot open"},
      {"v4l2://?depth=/dev/null", "/dev/null: not a V4L2 device"},
  };
  for (const auto& [uri, expected] : cases) {
    try {
      V4l2Source source(uri, system);
      ADD_FAILURE() << uri << " opened";
    } catch (const core::SourceError& e) {
      EXPECT_NE(std::string(e.what()).find(expected), std::string::npos) << e.what();
    }
  }
}

}  // namespace
}  // namespace tessera::drivers::v4l2
