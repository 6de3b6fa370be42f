#include <fstream>
#include <random>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>

#include "support/synthetic_plane.h"
#include "support/test_data.h"
#include "tessera/core/error.h"
#include "tessera/drivers/dataset_source.h"
#include "tessera/drivers/oni/oni_source.h"
#include "tessera/drivers/oni/oni_writer.h"

namespace tessera::drivers::oni {
namespace {

namespace fs = std::filesystem;

// Frames that exercise every token of the depth codec: smooth planes (small deltas, zero
// runs), holes (jumps to and from 0), seeded random speckle (large deltas), an odd width.
std::vector<core::Frame> codecStressFrames(int count, int width, int height) {
  std::mt19937 rng(1234);
  std::uniform_int_distribution<int> any_depth(0, 12000);
  std::uniform_int_distribution<int> pixel_x(0, width - 1), pixel_y(0, height - 1);
  core::Intrinsics k = test::kinectIntrinsics();
  k.width = width, k.height = height, k.cx = width / 2.0, k.cy = height / 2.0;
  std::vector<core::Frame> frames;
  for (int i = 0; i < count; ++i) {
    core::Isometry T_W_C = core::Isometry::Identity();
    T_W_C.translation().x() = 0.01 * i;
    core::Frame frame =
        test::renderPlane(k, T_W_C, Eigen::Vector3d(0.2, 0.1, -1).normalized(), -1.3);
    frame.depth_mm(cv::Rect(10, 10, 40, 30)).setTo(0);  // a hole
    for (int s = 0; s < 500; ++s) {
      frame.depth_mm.at<std::uint16_t>(pixel_y(rng), pixel_x(rng)) =
          static_cast<std::uint16_t>(any_depth(rng));
    }
    cv::randu(frame.rgb(cv::Rect(0, 0, width / 2, height / 4)), 0, 256);
    frame.index = static_cast<std::uint64_t>(i);
    frame.timestamp_ns = 1'000'000'000LL + i * 33'333'000LL;  // whole microseconds
    frame.T_W_C_gt = T_W_C;
    frames.push_back(std::move(frame));
  }
  return frames;
}

std::vector<core::Frame> readAll(core::FrameSource& source, std::string* end_problem = nullptr) {
  std::vector<core::Frame> frames;
  for (;;) {
    core::ReadResult result = source.read();
    if (result.status == core::ReadStatus::kEndOfData) {
      if (end_problem) *end_problem = result.problem;
      return frames;
    }
    if (result.status == core::ReadStatus::kFrame) frames.push_back(std::move(result.frame));
  }
}

bool identical(const cv::Mat& a, const cv::Mat& b) {
  return a.size() == b.size() && a.type() == b.type() && cv::norm(a, b, cv::NORM_INF) == 0.0;
}

void writeRecording(const fs::path& path, const std::vector<core::Frame>& frames,
                    const OniWriterOptions& options) {
  OniWriter writer(path, frames.front().intrinsics, frames.front().rgb.size(), options);
  for (const auto& frame : frames) writer.write(frame);
  writer.close();
  EXPECT_EQ(writer.framesWritten(), frames.size());
}

TEST(OniRoundTrip, SyntheticFramesAreBitExactWithEveryLosslessCodec) {
  const auto frames = codecStressFrames(6, 321, 240);
  for (const DepthCodec codec : {DepthCodec::k16zT, DepthCodec::kNone}) {
    const fs::path path = test::freshTempDir() / "synthetic.oni";
    OniWriterOptions options;
    options.depth_codec = codec;
    options.colour_codec = ColourCodec::kNone;
    writeRecording(path, frames, options);

    OniSource source(path);
    EXPECT_EQ(source.frameCount(), frames.size());
    ASSERT_TRUE(source.hasColour());
    std::string end_problem;
    const auto back = readAll(source, &end_problem);
    EXPECT_TRUE(end_problem.empty()) << end_problem;
    ASSERT_EQ(back.size(), frames.size());
    for (std::size_t i = 0; i < frames.size(); ++i) {
      EXPECT_TRUE(identical(back[i].depth_mm, frames[i].depth_mm)) << "depth of frame " << i;
      EXPECT_TRUE(identical(back[i].rgb, frames[i].rgb)) << "colour of frame " << i;
      EXPECT_EQ(back[i].timestamp_ns, frames[i].timestamp_ns);
    }
  }
}

TEST(OniRoundTrip, JpegColourIsCloseAndIntrinsicsComeFromTheFieldOfView) {
  const auto frames = codecStressFrames(3, 640, 480);
  const fs::path path = test::freshTempDir() / "jpeg.oni";
  writeRecording(path, frames, OniWriterOptions{});  // 16zT + JPEG

  OniSource source(path);
  EXPECT_NEAR(source.intrinsics().fx, frames[0].intrinsics.fx, 1e-3);
  EXPECT_NEAR(source.intrinsics().fy, frames[0].intrinsics.fy, 1e-3);
  const auto back = readAll(source);
  ASSERT_EQ(back.size(), 3u);
  for (std::size_t i = 0; i < back.size(); ++i) {
    EXPECT_TRUE(identical(back[i].depth_mm, frames[i].depth_mm));
    // The smooth part of the image (not the random block) survives JPEG closely.
    const cv::Rect smooth(0, 240, 640, 240);
    EXPECT_GT(cv::PSNR(back[i].rgb(smooth), frames[i].rgb(smooth)), 30.0);
  }
}

TEST(OniRoundTrip, RealTumFramesKeepDepthColourAndTimestamps) {
  TESSERA_REQUIRE_SHARED("rgbd/tum_fr1_rpy_40");
  DatasetSource tum(test::sharedData() / "rgbd/tum_fr1_rpy_40");
  std::vector<core::Frame> frames;
  for (int i = 0; i < 10; ++i) frames.push_back(tum.read().frame);
  const fs::path path = test::freshTempDir() / "tum.oni";
  OniWriterOptions options;
  options.colour_codec = ColourCodec::kNone;
  writeRecording(path, frames, options);
  EXPECT_LT(fs::file_size(path), 10 * (640 * 480 * 2 + 640 * 480 * 3));  // 16zT compresses

  OniSource source(path);
  const auto back = readAll(source);
  ASSERT_EQ(back.size(), frames.size());
  for (std::size_t i = 0; i < frames.size(); ++i) {
    EXPECT_TRUE(identical(back[i].depth_mm, frames[i].depth_mm)) << "depth of frame " << i;
    EXPECT_TRUE(identical(back[i].rgb, frames[i].rgb)) << "colour of frame " << i;
    EXPECT_EQ(back[i].timestamp_ns, frames[i].timestamp_ns);  // TUM stamps are whole microseconds
  }
}

TEST(OniRoundTrip, TruncatedFilePlaysWhatItCanThenEndsWithAClearMessage) {
  const auto frames = codecStressFrames(10, 320, 240);
  const fs::path path = test::freshTempDir() / "cut.oni";
  OniWriterOptions options;
  options.colour_codec = ColourCodec::kNone;
  writeRecording(path, frames, options);
  fs::resize_file(path, fs::file_size(path) * 6 / 10);

  OniSourceOptions source_options;
  source_options.frame_timeout_ms = 500;
  OniSource source(path, source_options);
  std::string end_problem;
  const auto back = readAll(source, &end_problem);
  EXPECT_GE(back.size(), 3u);
  EXPECT_LT(back.size(), 10u);
  for (std::size_t i = 0; i < back.size(); ++i) {
    EXPECT_TRUE(identical(back[i].depth_mm, frames[i].depth_mm)) << "frame " << i;
  }
  EXPECT_NE(end_problem.find(path.string()), std::string::npos) << end_problem;
  EXPECT_NE(end_problem.find("truncated"), std::string::npos) << end_problem;
  EXPECT_NE(end_problem.find("after frame " + std::to_string(back.size())), std::string::npos)
      << end_problem;
}

TEST(OniRoundTrip, CorruptHeaderIsAClearError) {
  const auto frames = codecStressFrames(2, 320, 240);
  const fs::path path = test::freshTempDir() / "bad.oni";
  writeRecording(path, frames, OniWriterOptions{});
  {
    std::fstream file(path, std::ios::in | std::ios::out | std::ios::binary);
    file.write("XXXX", 4);  // break the magic
  }
  try {
    OniSource source(path);
    FAIL() << "expected an error";
  } catch (const core::SourceError& e) {
    EXPECT_NE(std::string(e.what()).find(path.string()), std::string::npos) << e.what();
  }
  EXPECT_THROW(OniSource(path.parent_path() / "missing.oni"), core::SourceError);
}

TEST(OniSource, PlaysTheCommittedDefaultRecordingWithItsGroundTruth) {
  OniSource source(test::sourceDir() / "recordings/tum_fr1_rpy_20.oni");
  EXPECT_EQ(source.frameCount(), 20u);
  EXPECT_DOUBLE_EQ(source.intrinsics().fx, 517.3);  // from the sidecar, not the FOV
  EXPECT_DOUBLE_EQ(source.intrinsics().cy, 255.3);
  const auto frames = readAll(source);
  ASSERT_EQ(frames.size(), 20u);
  EXPECT_EQ(frames[0].timestamp_ns, 1305031234901998000);
  for (const auto& frame : frames) {
    ASSERT_TRUE(frame.T_W_C_gt.has_value());
    EXPECT_EQ(frame.rgb.size(), cv::Size(640, 480));
  }
  EXPECT_NEAR(frames[0].T_W_C_gt->translation().x(), 1.27657, 1e-4);

  source.rewind();  // plays again from the first frame
  const core::ReadResult again = source.read();
  ASSERT_EQ(again.status, core::ReadStatus::kFrame);
  EXPECT_EQ(again.frame.index, 0u);
  EXPECT_EQ(again.frame.timestamp_ns, frames[0].timestamp_ns);
  EXPECT_TRUE(identical(again.frame.depth_mm, frames[0].depth_mm));
}

}  // namespace
}  // namespace tessera::drivers::oni
