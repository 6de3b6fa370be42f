// V4l2Capture and V4l2Source on one depth node: negotiation, exact depth, failures mid-stream.
#include <chrono>
#include <random>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>

#include "drivers/v4l2_fake_device.h"
#include "tessera/core/error.h"
#include "tessera/drivers/v4l2/v4l2_capture.h"
#include "tessera/drivers/v4l2/v4l2_source.h"

namespace tessera::drivers::v4l2 {
namespace {

using fake::FakeCamera;
using fake::FakeEnding;

constexpr int kCaptureWidth = 16, kCaptureHeight = 12;
const std::string kDepthNode = "/dev/video2";
const std::string kDepthOnly = "v4l2://?depth=/dev/video2";

std::shared_ptr<FakeCamera> depthCamera(std::vector<std::uint32_t> formats) {
  auto camera = std::make_shared<FakeCamera>();
  camera->path = kDepthNode;
  camera->formats = std::move(formats);
  camera->width = kCaptureWidth;
  camera->height = kCaptureHeight;
  return camera;
}

// Seeded random depth covering the whole 16-bit range, 0 (invalid) and 65535 included.
std::vector<cv::Mat> randomDepths(int count) {
  std::mt19937 rng(42);
  std::uniform_int_distribution<int> any(0, 65535);
  std::vector<cv::Mat> depths;
  for (int i = 0; i < count; ++i) {
    cv::Mat depth(kCaptureHeight, kCaptureWidth, CV_16UC1);
    for (int v = 0; v < kCaptureHeight; ++v) {
      for (int u = 0; u < kCaptureWidth; ++u)
        depth.at<std::uint16_t>(v, u) = static_cast<std::uint16_t>(any(rng));
    }
    depth.at<std::uint16_t>(0, 0) = 0;
    depth.at<std::uint16_t>(0, 1) = 65535;
    depths.push_back(depth);
  }
  return depths;
}

void script(FakeCamera& camera, const std::vector<cv::Mat>& depths) {
  for (std::size_t i = 0; i < depths.size(); ++i) {
    camera.frames.push_back({1'000'000'000 + static_cast<std::int64_t>(i) * 33'333'000,
                             fake::z16Bytes(depths[i]), false});
  }
}

V4l2Options fakeOptions(const std::vector<std::shared_ptr<FakeCamera>>& cameras) {
  V4l2Options options;
  core::Intrinsics k;
  k.fx = k.fy = 20.0, k.cx = 7.5, k.cy = 5.5;
  options.intrinsics = k;
  options.make_device = fake::fakeFactory(cameras);
  return options;
}

bool identical(const cv::Mat& a, const cv::Mat& b) {
  return a.size() == b.size() && a.type() == b.type() && cv::norm(a, b, cv::NORM_INF) == 0.0;
}

CaptureConfig captureConfig(const std::vector<std::uint32_t>& formats) {
  CaptureConfig config;
  config.path = kDepthNode;
  config.formats = formats;
  return config;
}

TEST(Negotiation, PicksTheFirstPreferenceTheNodeOffersNotTheFirstOffered) {
  struct Case {
    std::vector<std::uint32_t> offered, wanted;
    std::uint32_t expected;
  };
  const Case cases[] = {
      {{V4L2_PIX_FMT_YUYV, V4L2_PIX_FMT_Y16, V4L2_PIX_FMT_Z16},
       depthFormatPreferences(),
       V4L2_PIX_FMT_Z16},
      {{V4L2_PIX_FMT_MJPEG, V4L2_PIX_FMT_Y16}, depthFormatPreferences(), V4L2_PIX_FMT_Y16},
      {{V4L2_PIX_FMT_RGB24, V4L2_PIX_FMT_MJPEG}, colourFormatPreferences(), V4L2_PIX_FMT_MJPEG},
  };
  for (const Case& c : cases) {
    const auto camera = depthCamera(c.offered);
    V4l2Capture capture(std::make_unique<fake::FakeV4l2Device>(camera), captureConfig(c.wanted));
    EXPECT_EQ(capture.format().fourcc, c.expected) << fourccName(capture.format().fourcc);
    EXPECT_EQ(camera->set_fourcc, c.expected);  // set on the node, not only chosen
    EXPECT_EQ(capture.format().width, kCaptureWidth);
    EXPECT_EQ(capture.offeredFormats(), c.offered);
  }
}

TEST(Negotiation, NoWantedFormatIsAnErrorListingWhatTheNodeOffers) {
  const auto camera = depthCamera({V4L2_PIX_FMT_YUYV, V4L2_PIX_FMT_MJPEG});
  try {
    V4l2Capture capture(std::make_unique<fake::FakeV4l2Device>(camera),
                        captureConfig(depthFormatPreferences()));
    FAIL() << "a node without Z16 or Y16 was accepted for depth";
  } catch (const core::SourceError& e) {
    const std::string message = e.what();
    for (const char* part : {"/dev/video2", "offers YUYV, MJPG", "Z16, Y16"}) {
      EXPECT_NE(message.find(part), std::string::npos) << "'" << part << "' not in: " << message;
    }
  }
  EXPECT_EQ(camera->closes, camera->opens);  // a failed negotiation lets go of the node
}

TEST(Negotiation, MetadataNodeIsRejectedByName) {
  const auto camera = depthCamera({V4L2_PIX_FMT_Z16});
  camera->device_caps = V4L2_CAP_META_CAPTURE | V4L2_CAP_STREAMING;
  EXPECT_THROW(
      {
        try {
          V4l2Capture capture(std::make_unique<fake::FakeV4l2Device>(camera),
                              captureConfig(depthFormatPreferences()));
        } catch (const core::SourceError& e) {
          EXPECT_NE(std::string(e.what()).find("/dev/video2: not a video capture node"),
                    std::string::npos)
              << e.what();
          throw;
        }
      },
      core::SourceError);
}

TEST(Capture, Z16DepthRoundTripsExactlyWithTimestamps) {
  const auto camera = depthCamera({V4L2_PIX_FMT_Z16});
  const auto depths = randomDepths(6);  // more frames than buffers: every buffer is reused
  script(*camera, depths);
  camera->ending = FakeEnding::kDisappearOnDequeue;
  V4l2Source source(kDepthOnly, fakeOptions({camera}));
  for (std::size_t i = 0; i < depths.size(); ++i) {
    core::ReadResult result = source.read();
    ASSERT_EQ(result.status, core::ReadStatus::kFrame) << result.problem;
    EXPECT_TRUE(identical(result.frame.depth_mm, depths[i])) << "frame " << i;
    EXPECT_EQ(result.frame.timestamp_ns, camera->frames[i].timestamp_ns);
    EXPECT_EQ(result.frame.index, i);
    EXPECT_TRUE(result.frame.rgb.empty());
    EXPECT_EQ(result.frame.intrinsics.width, kCaptureWidth);
  }
  EXPECT_EQ(source.read().status, core::ReadStatus::kEndOfData);
  EXPECT_EQ(camera->buffers_granted, 4u);
}

TEST(Capture, ShortReadIsABadFrameAndTheNextFrameIsIntact) {
  const auto camera = depthCamera({V4L2_PIX_FMT_Z16});
  const auto depths = randomDepths(3);
  script(*camera, depths);
  camera->frames[1].bytes.resize(camera->frames[1].bytes.size() / 2);
  V4l2Source source(kDepthOnly, fakeOptions({camera}));
  EXPECT_EQ(source.read().status, core::ReadStatus::kFrame);
  const core::ReadResult bad = source.read();
  ASSERT_EQ(bad.status, core::ReadStatus::kBadFrame);
  EXPECT_NE(bad.problem.find("/dev/video2: short depth frame"), std::string::npos) << bad.problem;
  EXPECT_NE(bad.problem.find("192 of 384 bytes"), std::string::npos) << bad.problem;
  const core::ReadResult next = source.read();
  ASSERT_EQ(next.status, core::ReadStatus::kFrame) << next.problem;
  EXPECT_TRUE(identical(next.frame.depth_mm, depths[2]));
  EXPECT_EQ(next.frame.index, 2u);
}

TEST(Capture, DeviceThatDisappearsEndsTheStreamNamingItAfterItsFrames) {
  for (const auto& [ending, error] : {std::pair{FakeEnding::kDisappearOnDequeue, ENODEV},
                                      std::pair{FakeEnding::kPollError, EIO}}) {
    const auto camera = depthCamera({V4L2_PIX_FMT_Z16});
    const auto depths = randomDepths(3);
    script(*camera, depths);
    camera->ending = ending;
    camera->end_errno = error;
    V4l2Source source(kDepthOnly, fakeOptions({camera}));
    for (const cv::Mat& depth : depths) {
      const core::ReadResult result = source.read();
      ASSERT_EQ(result.status, core::ReadStatus::kFrame) << result.problem;
      EXPECT_TRUE(identical(result.frame.depth_mm, depth));
    }
    const core::ReadResult end = source.read();
    EXPECT_EQ(end.status, core::ReadStatus::kEndOfData);
    EXPECT_NE(end.problem.find("/dev/video2: the depth device disappeared"), std::string::npos)
        << end.problem;
    EXPECT_NE(end.problem.find("after 3 frames"), std::string::npos) << end.problem;
    const core::ReadResult after = source.read();  // stays ended, says it once
    EXPECT_EQ(after.status, core::ReadStatus::kEndOfData);
    EXPECT_TRUE(after.problem.empty());
  }
}

TEST(Capture, StalledStreamEndsAfterTheStallTimeout) {
  const auto camera = depthCamera({V4L2_PIX_FMT_Z16});
  script(*camera, randomDepths(2));
  V4l2Options options = fakeOptions({camera});
  options.stall_timeout_ms = 150;
  V4l2Source source(kDepthOnly, options);
  ASSERT_EQ(source.read().status, core::ReadStatus::kFrame);
  ASSERT_EQ(source.read().status, core::ReadStatus::kFrame);
  const auto start = std::chrono::steady_clock::now();
  const core::ReadResult end = source.read();
  const auto waited = std::chrono::steady_clock::now() - start;
  EXPECT_EQ(end.status, core::ReadStatus::kEndOfData);
  EXPECT_NE(end.problem.find("/dev/video2: the depth stream stalled: no frame for 150 ms"),
            std::string::npos)
      << end.problem;
  EXPECT_GE(waited, std::chrono::milliseconds(140));  // the stall clock started at frame 2
  EXPECT_LT(waited, std::chrono::milliseconds(1000));
}

TEST(Capture, DestroyingTheSourceReleasesTheNode) {
  const auto camera = depthCamera({V4L2_PIX_FMT_Z16});
  script(*camera, randomDepths(2));
  {
    V4l2Source source(kDepthOnly, fakeOptions({camera}));
    EXPECT_EQ(source.read().status, core::ReadStatus::kFrame);
    EXPECT_EQ(camera->streams_on, 1);
  }
  EXPECT_EQ(camera->streams_off, 1);
  EXPECT_EQ(camera->maps, 4);
  EXPECT_EQ(camera->unmaps, 4);
  EXPECT_EQ(camera->opens, 1);
  EXPECT_EQ(camera->closes, 1);
}

TEST(Capture, Y16IsReadAsMillimetres) {
  const auto camera = depthCamera({V4L2_PIX_FMT_Y16});
  const auto depths = randomDepths(1);
  script(*camera, depths);
  V4l2Source source(kDepthOnly, fakeOptions({camera}));
  const core::ReadResult result = source.read();
  ASSERT_EQ(result.status, core::ReadStatus::kFrame) << result.problem;
  EXPECT_EQ(source.depthCapture().format().fourcc, V4L2_PIX_FMT_Y16);
  EXPECT_TRUE(identical(result.frame.depth_mm, depths[0]));
}

}  // namespace
}  // namespace tessera::drivers::v4l2
