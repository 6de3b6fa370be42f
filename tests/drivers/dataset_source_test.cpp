#include <algorithm>
#include <cmath>
#include <fstream>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "support/test_data.h"
#include "tessera/core/error.h"
#include "tessera/drivers/dataset_source.h"

namespace tessera::drivers {
namespace {

namespace fs = std::filesystem;

// Median of the valid (non-zero) depth values in millimetres.
double medianValidDepthMm(const cv::Mat& depth_mm) {
  std::vector<std::uint16_t> values;
  for (int v = 0; v < depth_mm.rows; ++v) {
    for (int u = 0; u < depth_mm.cols; ++u) {
      const auto z = depth_mm.at<std::uint16_t>(v, u);
      if (z > 0) values.push_back(z);
    }
  }
  if (values.empty()) return 0.0;
  std::nth_element(values.begin(), values.begin() + static_cast<long>(values.size() / 2),
                   values.end());
  return values[values.size() / 2];
}

// Reads every frame; returns the good ones and counts the bad ones.
std::vector<core::Frame> readAll(core::FrameSource& source, std::size_t* bad = nullptr,
                                 std::vector<std::string>* problems = nullptr) {
  std::vector<core::Frame> frames;
  for (;;) {
    core::ReadResult result = source.read();
    if (result.status == core::ReadStatus::kEndOfData) break;
    if (result.status == core::ReadStatus::kBadFrame) {
      if (bad) ++*bad;
      if (problems) problems->push_back(result.problem);
      continue;
    }
    frames.push_back(std::move(result.frame));
  }
  return frames;
}

// Copies the first `count` TUM frames into `dir` (named so the fr1 calibration applies).
fs::path copyTumSubset(const fs::path& dir, std::size_t count, bool with_associations) {
  const fs::path from = test::sharedData() / "rgbd/tum_fr1_rpy_40";
  const fs::path to = dir / "rgbd_dataset_freiburg1_rpy_part";
  fs::create_directories(to / "rgb");
  fs::create_directories(to / "depth");
  std::ifstream assoc(from / "associations.txt");
  std::ofstream rgb_txt(to / "rgb.txt"), depth_txt(to / "depth.txt");
  std::ofstream assoc_out;
  if (with_associations) assoc_out.open(to / "associations.txt");
  std::string line;
  std::size_t copied = 0;
  while (copied < count && std::getline(assoc, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream in(line);
    std::string t_rgb, f_rgb, t_depth, f_depth;
    in >> t_rgb >> f_rgb >> t_depth >> f_depth;
    fs::copy_file(from / f_rgb, to / f_rgb);
    fs::copy_file(from / f_depth, to / f_depth);
    rgb_txt << t_rgb << ' ' << f_rgb << '\n';
    depth_txt << t_depth << ' ' << f_depth << '\n';
    if (with_associations) assoc_out << line << '\n';
    ++copied;
  }
  fs::copy_file(from / "groundtruth.txt", to / "groundtruth.txt");
  return to;
}

TEST(DatasetSource, ReadsTumWithPublishedCalibrationAndInterpolatedGroundTruth) {
  TESSERA_REQUIRE_SHARED("rgbd/tum_fr1_rpy_40");
  DatasetSource source(test::sharedData() / "rgbd/tum_fr1_rpy_40");
  EXPECT_EQ(source.layout(), DatasetLayout::kTum);
  EXPECT_DOUBLE_EQ(source.intrinsics().fx, 517.3);  // freiburg1, from the folder name
  EXPECT_DOUBLE_EQ(source.intrinsics().cy, 255.3);
  ASSERT_EQ(source.frameCount(), 40u);
  EXPECT_EQ(source.framesWithPose(), 40u);

  std::size_t bad = 0;
  const auto frames = readAll(source, &bad);
  ASSERT_EQ(frames.size(), 40u);
  EXPECT_EQ(bad, 0u);
  const core::Frame& first = frames.front();
  EXPECT_EQ(first.timestamp_ns, 1305031234901998000);  // the depth timestamp, exactly
  EXPECT_EQ(first.depth_mm.type(), CV_16UC1);
  EXPECT_EQ(first.rgb.type(), CV_8UC3);
  EXPECT_EQ(first.depth_mm.size(), cv::Size(640, 480));
  // The file's raw valid median is 14913 (decoded independently); at 5000 units per metre
  // that is 2982.6 mm.
  EXPECT_NEAR(medianValidDepthMm(first.depth_mm), 2982.6, 1.0);
  // Ground truth between the mocap samples at .8931 and .9031 s (alpha 0.8898).
  ASSERT_TRUE(first.T_W_C_gt.has_value());
  EXPECT_NEAR(first.T_W_C_gt->translation().x(), 1.27657, 1e-4);
  EXPECT_NEAR(first.T_W_C_gt->translation().y(), 0.63222, 1e-4);
  EXPECT_NEAR(first.T_W_C_gt->translation().z(), 1.53571, 1e-4);
  for (std::size_t i = 1; i < frames.size(); ++i) {
    EXPECT_GT(frames[i].timestamp_ns, frames[i - 1].timestamp_ns);
  }
}

TEST(DatasetSource, AssociatesTumByTimestampWithoutAssociationsFile) {
  TESSERA_REQUIRE_SHARED("rgbd/tum_fr1_rpy_40");
  const fs::path dir = copyTumSubset(test::freshTempDir(), 5, /*with_associations=*/false);
  DatasetSource source(dir);
  const auto frames = readAll(source);
  ASSERT_EQ(frames.size(), 5u);
  EXPECT_EQ(frames[0].timestamp_ns, 1305031234901998000);
  EXPECT_TRUE(frames[4].T_W_C_gt.has_value());
}

TEST(DatasetSource, CorruptDepthPngIsCountedSkippedAndNamed) {
  TESSERA_REQUIRE_SHARED("rgbd/tum_fr1_rpy_40");
  const fs::path dir = copyTumSubset(test::freshTempDir(), 5, /*with_associations=*/true);
  // Truncate the third depth image to a few bytes of its header.
  std::vector<fs::path> depths;
  for (const auto& entry : fs::directory_iterator(dir / "depth")) depths.push_back(entry.path());
  std::sort(depths.begin(), depths.end());
  fs::resize_file(depths[2], 40);

  DatasetSource source(dir);
  std::size_t bad = 0;
  std::vector<std::string> problems;
  const auto frames = readAll(source, &bad, &problems);
  EXPECT_EQ(frames.size(), 4u);
  EXPECT_EQ(bad, 1u);
  ASSERT_EQ(problems.size(), 1u);
  EXPECT_NE(problems[0].find(depths[2].filename().string()), std::string::npos) << problems[0];
  EXPECT_EQ(frames[2].index, 3u);  // the stream went on after the bad frame
}

TEST(DatasetSource, MissingColourImageIsABadFrame) {
  TESSERA_REQUIRE_SHARED("rgbd/tum_fr1_rpy_40");
  const fs::path dir = copyTumSubset(test::freshTempDir(), 3, /*with_associations=*/true);
  for (const auto& entry : fs::directory_iterator(dir / "rgb")) {
    fs::remove(entry.path());
    break;
  }
  DatasetSource source(dir);
  std::size_t bad = 0;
  EXPECT_EQ(readAll(source, &bad).size(), 2u);
  EXPECT_EQ(bad, 1u);
}

TEST(DatasetSource, TumFolderWithoutCameraNameNeedsIntrinsics) {
  TESSERA_REQUIRE_SHARED("rgbd/tum_fr1_rpy_40");
  const fs::path base = test::freshTempDir();
  const fs::path dir = copyTumSubset(base, 2, true);
  const fs::path renamed = base / "desk_sequence";
  fs::rename(dir, renamed);
  try {
    DatasetSource source(renamed);
    FAIL() << "expected a missing-intrinsics error";
  } catch (const core::ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("--intrinsics"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("desk_sequence"), std::string::npos) << e.what();
  }
  // "fr2" as a word of the name selects the freiburg2 calibration; "frame2" does not.
  fs::rename(renamed, base / "tum_fr2_desk");
  EXPECT_DOUBLE_EQ(DatasetSource(base / "tum_fr2_desk").intrinsics().fx, 520.9);
  fs::rename(base / "tum_fr2_desk", base / "frame2");
  EXPECT_THROW(DatasetSource(base / "frame2"), core::ConfigError);
  fs::rename(base / "frame2", renamed);

  DatasetOptions options;
  options.intrinsics = core::parseIntrinsicsSpec("525,525,319.5,239.5");
  DatasetSource source(renamed, options);
  EXPECT_DOUBLE_EQ(source.intrinsics().fx, 525.0);
  EXPECT_EQ(readAll(source).size(), 2u);
}

TEST(DatasetSource, ReadsSlambookKinectPgmDepth) {
  TESSERA_REQUIRE_SHARED("rgbd/kinect_diningroom_5");
  const fs::path dir = test::sharedData() / "rgbd/kinect_diningroom_5";
  EXPECT_THROW(DatasetSource{dir}, core::ConfigError);  // the layout carries no intrinsics

  DatasetOptions options;
  options.intrinsics = core::parseIntrinsicsSpec("518.0,519.0,325.5,253.5");
  DatasetSource source(dir, options);
  EXPECT_EQ(source.layout(), DatasetLayout::kSlambook);
  EXPECT_DOUBLE_EQ(source.depthUnitsPerMetre(), 1000.0);
  const auto frames = readAll(source);
  ASSERT_EQ(frames.size(), 5u);
  // SOURCE.txt: big-endian millimetres, observed median 2877 over the set.
  EXPECT_NEAR(medianValidDepthMm(frames[0].depth_mm), 2877.0, 600.0);
  ASSERT_TRUE(frames[0].T_W_C_gt.has_value());
  EXPECT_NEAR(frames[0].T_W_C_gt->translation().x(), -0.228993, 1e-6);
  EXPECT_NEAR(frames[4].T_W_C_gt->translation().z(), 1.6215, 1e-6);
}

TEST(DatasetSource, ReadsSlambookPngDepthWithNegativeFocalLength) {
  TESSERA_REQUIRE_SHARED("rgbd/iclnuim_livingroom_5");
  DatasetOptions options;
  options.intrinsics = core::parseIntrinsicsSpec("481.2,-480.0,319.5,239.5");
  DatasetSource source(test::sharedData() / "rgbd/iclnuim_livingroom_5", options);
  EXPECT_EQ(source.layout(), DatasetLayout::kSlambook);
  EXPECT_DOUBLE_EQ(source.depthUnitsPerMetre(), 5000.0);
  const auto frames = readAll(source);
  ASSERT_EQ(frames.size(), 5u);
  double min_value = 0, max_value = 0;
  cv::minMaxLoc(frames[0].depth_mm, &min_value, &max_value);
  // SOURCE.txt: raw values 3555-21415 at 5000 per metre over the set.
  EXPECT_GE(min_value, 3555.0 / 5 - 1);
  EXPECT_LE(max_value, 21415.0 / 5 + 1);
  EXPECT_LT(frames[0].intrinsics.fy, 0.0);
}

TEST(DatasetSource, ReadsRedwoodWithJsonIntrinsicsAndLogTrajectory) {
  TESSERA_REQUIRE_SHARED("rgbd/open3d_testdata");
  DatasetSource source(test::sharedData() / "rgbd/open3d_testdata");
  EXPECT_EQ(source.layout(), DatasetLayout::kRedwood);
  EXPECT_DOUBLE_EQ(source.intrinsics().fx, 525.0);
  EXPECT_DOUBLE_EQ(source.intrinsics().cx, 319.5);
  const auto frames = readAll(source);
  ASSERT_EQ(frames.size(), 5u);
  ASSERT_TRUE(frames[0].T_W_C_gt.has_value());
  EXPECT_NEAR(frames[0].T_W_C_gt->translation().z(), 2.1264800183565487, 1e-12);
  EXPECT_NEAR(frames[1].T_W_C_gt->translation().y(), 0.5963093994288613, 1e-12);
  const double median = medianValidDepthMm(frames[0].depth_mm);
  EXPECT_GT(median, 300.0);
  EXPECT_LT(median, 5000.0);
}

// Writes a 7-Scenes sequence folder with one frame per colour image (640x480 BGR): PNG colour,
// depth 1500 + 100 i mm with a 65535 corner, pose x = 0.1 i m, and a camera-intrinsics.txt.
void writeSevenScenesSequence(const fs::path& dir, const std::vector<cv::Mat>& colours) {
  fs::create_directories(dir);
  for (std::size_t i = 0; i < colours.size(); ++i) {
    const std::string stem = cv::format("frame-%06zu", i);
    cv::Mat depth(480, 640, CV_16UC1, cv::Scalar(1500 + 100 * static_cast<double>(i)));
    depth(cv::Rect(0, 0, 10, 10)).setTo(65535);  // 7-Scenes' invalid marker
    cv::imwrite((dir / (stem + ".depth.png")).string(), depth);
    cv::imwrite((dir / (stem + ".color.png")).string(), colours[i]);
    std::ofstream(dir / (stem + ".pose.txt"))
        << "1 0 0 " << 0.1 * static_cast<double>(i) << "\n0 1 0 0\n0 0 1 0\n0 0 0 1\n";
  }
  std::ofstream(dir / "camera-intrinsics.txt") << "585 0 320\n0 585 240\n0 0 1\n";
}

// Copies a 7-Scenes folder, re-encoding each frame-N.color.png as frame-N.color.jpg
// (quality 95), the way several public copies of the dataset ship.
void copySevenScenesAsJpeg(const fs::path& from, const fs::path& to) {
  fs::create_directories(to);
  const std::string png_suffix = ".color.png";
  for (const auto& entry : fs::directory_iterator(from)) {
    const std::string name = entry.path().filename().string();
    if (!name.ends_with(png_suffix)) {
      fs::copy_file(entry.path(), to / name);
      continue;
    }
    const std::string jpg_name = name.substr(0, name.size() - png_suffix.size()) + ".color.jpg";
    ASSERT_TRUE(cv::imwrite((to / jpg_name).string(), cv::imread(entry.path().string()),
                            {cv::IMWRITE_JPEG_QUALITY, 95}))
        << jpg_name;
  }
}

TEST(DatasetSource, ReadsSevenScenesFolder) {
  const fs::path dir = test::freshTempDir() / "seq-01";
  writeSevenScenesSequence(
      dir, std::vector<cv::Mat>(3, cv::Mat(480, 640, CV_8UC3, cv::Scalar(10, 20, 30))));

  DatasetSource source(dir);
  EXPECT_EQ(source.layout(), DatasetLayout::kSevenScenes);
  EXPECT_DOUBLE_EQ(source.intrinsics().fy, 585.0);
  const auto frames = readAll(source);
  ASSERT_EQ(frames.size(), 3u);
  EXPECT_EQ(frames[2].depth_mm.at<std::uint16_t>(100, 100), 1700);
  EXPECT_EQ(frames[0].depth_mm.at<std::uint16_t>(5, 5), 0);             // 65535 became invalid
  EXPECT_EQ(frames[0].rgb.at<cv::Vec3b>(0, 0), cv::Vec3b(30, 20, 10));  // BGR file -> RGB
  ASSERT_TRUE(frames[2].T_W_C_gt.has_value());
  EXPECT_NEAR(frames[2].T_W_C_gt->translation().x(), 0.2, 1e-12);
  EXPECT_GT(frames[1].timestamp_ns, frames[0].timestamp_ns);
}

TEST(DatasetSource, ReadsSevenScenesFolderWithJpegColour) {
  // Smooth seeded texture (slow waves, per channel): flat colour would survive JPEG exactly,
  // pure noise would lose far more than a real photo does.
  cv::RNG rng(7);
  std::vector<cv::Mat> colours;
  for (int i = 0; i < 3; ++i) {
    cv::Mat colour(480, 640, CV_8UC3);
    cv::Vec3d kx, ky, phase;
    for (int c = 0; c < 3; ++c) {
      kx[c] = rng.uniform(0.01, 0.08), ky[c] = rng.uniform(0.01, 0.08);
      phase[c] = rng.uniform(0.0, 6.28);
    }
    for (int v = 0; v < colour.rows; ++v) {
      for (int u = 0; u < colour.cols; ++u) {
        for (int c = 0; c < 3; ++c) {
          colour.at<cv::Vec3b>(v, u)[c] = cv::saturate_cast<std::uint8_t>(
              128 + 60 * std::sin(kx[c] * u + phase[c]) + 60 * std::sin(ky[c] * v));
        }
      }
    }
    colours.push_back(colour);
  }
  const fs::path base = test::freshTempDir();
  const fs::path png_dir = base / "png" / "seq-01";
  const fs::path jpg_dir = base / "jpg" / "seq-01";
  writeSevenScenesSequence(png_dir, colours);
  copySevenScenesAsJpeg(png_dir, jpg_dir);
  ASSERT_TRUE(fs::exists(jpg_dir / "frame-000000.color.jpg"));
  ASSERT_FALSE(fs::exists(jpg_dir / "frame-000000.color.png"));

  EXPECT_EQ(detectDatasetLayout(jpg_dir), DatasetLayout::kSevenScenes);
  DatasetSource png_source(png_dir);
  DatasetSource jpg_source(jpg_dir);
  EXPECT_EQ(jpg_source.layout(), DatasetLayout::kSevenScenes);
  ASSERT_EQ(jpg_source.frameCount().value_or(0), png_source.frameCount().value_or(0));
  std::size_t bad = 0;
  const auto png_frames = readAll(png_source);
  const auto jpg_frames = readAll(jpg_source, &bad);
  EXPECT_EQ(bad, 0u);
  ASSERT_EQ(png_frames.size(), 3u);
  ASSERT_EQ(jpg_frames.size(), png_frames.size());
  for (std::size_t i = 0; i < png_frames.size(); ++i) {
    const core::Frame& png = png_frames[i];
    const core::Frame& jpg = jpg_frames[i];
    ASSERT_EQ(jpg.depth_mm.size(), png.depth_mm.size());
    EXPECT_EQ(cv::norm(jpg.depth_mm, png.depth_mm, cv::NORM_INF), 0.0) << "frame " << i;
    ASSERT_EQ(jpg.rgb.size(), png.rgb.size());
    ASSERT_EQ(jpg.rgb.type(), png.rgb.type());
    // JPEG is lossy: close to the PNG colour, but not identical.
    const double mean_abs_error =
        cv::norm(jpg.rgb, png.rgb, cv::NORM_L1) / static_cast<double>(png.rgb.total() * 3);
    EXPECT_GT(mean_abs_error, 0.0) << "frame " << i;
    EXPECT_LT(mean_abs_error, 3.0) << "frame " << i;
    ASSERT_TRUE(png.T_W_C_gt.has_value());
    ASSERT_TRUE(jpg.T_W_C_gt.has_value());
    EXPECT_TRUE(jpg.T_W_C_gt->matrix() == png.T_W_C_gt->matrix()) << "frame " << i;
  }

  // Where both exist the PNG is read; a .jpeg extension is read too.
  fs::copy_file(png_dir / "frame-000000.color.png", jpg_dir / "frame-000000.color.png");
  fs::rename(jpg_dir / "frame-000001.color.jpg", jpg_dir / "frame-000001.color.jpeg");
  DatasetSource mixed_source(jpg_dir);
  const auto mixed_frames = readAll(mixed_source);
  ASSERT_EQ(mixed_frames.size(), 3u);
  EXPECT_EQ(cv::norm(mixed_frames[0].rgb, png_frames[0].rgb, cv::NORM_INF), 0.0);
  EXPECT_EQ(cv::norm(mixed_frames[1].rgb, jpg_frames[1].rgb, cv::NORM_INF), 0.0);
}

TEST(DatasetSource, UnknownFolderListsTheKnownLayouts) {
  const fs::path dir = test::freshTempDir();
  std::ofstream(dir / "notes.txt") << "nothing here\n";
  try {
    DatasetSource source(dir);
    FAIL() << "expected an unknown-layout error";
  } catch (const core::SourceError& e) {
    const std::string message = e.what();
    for (const char* layout : {"TUM RGB-D", "7-Scenes", "Redwood", "slambook"}) {
      EXPECT_NE(message.find(layout), std::string::npos) << message;
    }
    EXPECT_NE(message.find(dir.string()), std::string::npos) << message;
  }
  EXPECT_THROW(DatasetSource(dir / "missing"), core::SourceError);
}

}  // namespace
}  // namespace tessera::drivers
