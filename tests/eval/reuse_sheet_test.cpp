#include <fstream>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "support/test_data.h"
#include "tessera/core/error.h"
#include "tessera/eval/reuse_sheet.h"

namespace tessera::eval {
namespace {

using nlohmann::json;
namespace fs = std::filesystem;

constexpr int kWidth = 80, kHeight = 60;  // each patch's texel grid
constexpr int kShift = 10;                // patch 2's texel (c, r) is texture 1's pixel (c + 10, r)

void writeRgba(const fs::path& path, const cv::Mat& rgb, const cv::Mat& alpha) {
  cv::Mat bgra;
  cv::cvtColor(rgb, bgra, cv::COLOR_RGB2BGRA);
  cv::insertChannel(alpha, bgra, 3);
  ASSERT_TRUE(cv::imwrite(path.string(), bgra));
}

json patchEntry(int id, const json& instance) {
  const std::string image = "textures/patch_" + std::to_string(id) + ".png";
  return json{{"id", id},
              {"texture",
               {{"image", image},
                {"state_image", "textures/patch_" + std::to_string(id) + "_state.png"},
                {"texel_m", 0.005},
                {"origin_uv", {0.0, 0.0}},
                {"x_axis", {1.0, 0.0}},
                {"y_axis", {0.0, 1.0}},
                {"width", kWidth},
                {"height", kHeight}}},
              {"instance", instance}};
}

json instanceEntry(bool reused, double tx) {
  return json{{"texture_id", 1},
              {"image", "textures/texture_1.png"},
              {"width", kWidth},
              {"height", kHeight},
              {"transform", {1.0, 0.0, tx, 0.0}},
              {"tiled", false},
              {"reused", reused},
              {"psnr_db", reused ? json(99.0) : json(nullptr)}};
}

// A run of two patches: patch 1 stored its noise bitmap as texture 1; patch 2 saw the same
// surface 10 texels further along and reuses texture 1 exactly (its last 10 columns unseen).
fs::path writeFakeRun(bool with_reuse = true) {
  const fs::path run = test::freshTempDir();
  fs::create_directories(run / "textures");
  cv::Mat texture(kHeight, kWidth, CV_8UC3);
  cv::RNG rng(7);
  rng.fill(texture, cv::RNG::UNIFORM, 0, 256);
  const cv::Mat opaque(kHeight, kWidth, CV_8UC1, cv::Scalar(255));
  writeRgba(run / "textures/patch_1.png", texture, opaque);
  writeRgba(run / "textures/texture_1.png", texture, opaque);
  cv::Mat second(kHeight, kWidth, CV_8UC3, cv::Scalar::all(0));
  cv::Mat second_alpha(kHeight, kWidth, CV_8UC1, cv::Scalar(0));
  const cv::Rect seen(0, 0, kWidth - kShift, kHeight);
  texture(seen + cv::Point(kShift, 0)).copyTo(second(seen));
  second_alpha(seen).setTo(255);
  writeRgba(run / "textures/patch_2.png", second, second_alpha);
  const json patches = {
      {"patches",
       {patchEntry(1, instanceEntry(false, 0.0)),
        patchEntry(2, with_reuse ? instanceEntry(true, kShift) : json(nullptr))}}};
  std::ofstream(run / "patches.json") << patches.dump(2);
  return run;
}

TEST(ReuseSheet, HasOneRowPerReuseWithTheOwnBitmapTheRenderAndTheirDifference) {
  const fs::path run = writeFakeRun();
  const ReuseSheetOptions options;
  ASSERT_EQ(writeReuseSheet(run, options), 1);
  const cv::Mat sheet = cv::imread((run / "reuse_sheet.png").string(), cv::IMREAD_COLOR);
  ASSERT_FALSE(sheet.empty());
  // One row; each 80 x 60 panel scaled to the row height: 240 x 180.
  const int gap = options.gap_px;
  const int panel_w = kWidth * options.row_height_px / kHeight;
  EXPECT_EQ(sheet.rows, gap + options.label_height_px + options.row_height_px + gap);
  EXPECT_GE(sheet.cols, 3 * panel_w + 4 * gap);
  const int top = gap + options.label_height_px;
  // The difference panel: black where both panels have a colour (an exact reuse).
  const cv::Point difference_centre(gap + 2 * (panel_w + gap) + panel_w / 2,
                                    top + options.row_height_px / 2);
  EXPECT_EQ(sheet.at<cv::Vec3b>(difference_centre), cv::Vec3b(0, 0, 0));
  // The render: its last 10 columns map beyond texture 1, so they show the empty checkerboard.
  const cv::Vec3b empty = sheet.at<cv::Vec3b>(top + 2, gap + panel_w + gap + panel_w - 2);
  EXPECT_TRUE(empty == cv::Vec3b(70, 70, 70) || empty == cv::Vec3b(100, 100, 100)) << empty;
  // The own bitmap panel shows patch 2's texel (0, 0) = texture 1's pixel (10, 0), scaled x3.
  const cv::Mat texture = cv::imread((run / "textures/texture_1.png").string(), cv::IMREAD_COLOR);
  EXPECT_EQ(sheet.at<cv::Vec3b>(top + 1, gap + 1), texture.at<cv::Vec3b>(0, kShift));
}

TEST(ReuseSheet, NoReuseNoSheet) {
  const fs::path run = writeFakeRun(/*with_reuse=*/false);
  EXPECT_EQ(writeReuseSheet(run), 0);
  EXPECT_FALSE(fs::exists(run / "reuse_sheet.png"));
}

TEST(ReuseSheet, AMissingTextureImageIsAnErrorNamingIt) {
  const fs::path run = writeFakeRun();
  fs::remove(run / "textures/texture_1.png");
  try {
    writeReuseSheet(run);
    FAIL() << "expected an error";
  } catch (const core::Error& e) {
    EXPECT_NE(std::string(e.what()).find("texture_1.png"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace tessera::eval
