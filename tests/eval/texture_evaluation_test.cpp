#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "support/test_data.h"
#include "tessera/core/config.h"
#include "tessera/core/error.h"
#include "tessera/drivers/synthetic/texture.h"
#include "tessera/eval/texture_evaluation.h"

namespace tessera::eval {
namespace {

using nlohmann::json;
namespace fs = std::filesystem;

const char* kTiles =
    "{id: tiles, generator: tiles, seed: 3, tile_m: 0.3, grout_m: 0.006, tiles_per_period: 2}";

// The floor z = 0 (normal +z, the camera above it), 2 m x 2 m, tiled.
json truthScene() {
  return json{{"textures", {{{"id", "tiles"}, {"definition_yaml", kTiles}}}},
              {"planes",
               {{{"id", "floor"},
                 {"normal", {0.0, 0.0, 1.0}},
                 {"offset_m", 0.0},
                 {"origin", {0.0, 0.0, 0.0}},
                 {"u_axis", {1.0, 0.0, 0.0}},
                 {"v_axis", {0.0, 1.0, 0.0}},
                 {"polygon_uv", {{0.0, 0.0}, {2.0, 0.0}, {2.0, 2.0}, {0.0, 2.0}}},
                 {"texture", "tiles"},
                 {"texture_to_plane",
                  {{"rotation_rad", 0.0}, {"scale", 1.0}, {"offset_m", {0.0, 0.0}}}}}}}};
}

// A run whose one patch covers [0.5, 1.5]^2 of the floor with 5 mm texels, its bitmap the
// true texture at each texel centre moved by `error` (metres, in the plane).
json writeRun(const fs::path& run_dir, const Eigen::Vector2d& error) {
  const core::ConfigDocument definition = core::ConfigDocument::fromString(kTiles, "test");
  const auto texture = drivers::synthetic::makeTexture(definition.root(), ".");
  const double t = 0.005;
  const int n = 200;
  cv::Mat bgra(n, n, CV_8UC4), state(n, n, CV_8UC1, cv::Scalar(255));
  for (int r = 0; r < n; ++r) {
    for (int c = 0; c < n; ++c) {
      const cv::Vec3f rgb =
          texture->colour(0.5 + (c + 0.5) * t + error.x(), 0.5 + (r + 0.5) * t + error.y());
      bgra.at<cv::Vec4b>(r, c) = cv::Vec4b(cv::saturate_cast<std::uint8_t>(rgb[2]),
                                           cv::saturate_cast<std::uint8_t>(rgb[1]),
                                           cv::saturate_cast<std::uint8_t>(rgb[0]), 255);
    }
  }
  fs::create_directories(run_dir / "textures");
  cv::imwrite((run_dir / "textures/patch_1.png").string(), bgra);
  cv::imwrite((run_dir / "textures/patch_1_state.png").string(), state);
  return json{{"patches",
               {{{"id", 1},
                 {"origin", {0.0, 0.0, 0.0}},
                 {"u_axis", {1.0, 0.0, 0.0}},
                 {"v_axis", {0.0, 1.0, 0.0}},
                 {"texture",
                  {{"image", "textures/patch_1.png"},
                   {"state_image", "textures/patch_1_state.png"},
                   {"texel_m", t},
                   {"origin_uv", {0.5, 0.5}},
                   {"x_axis", {1.0, 0.0}},
                   {"y_axis", {0.0, 1.0}},
                   {"width", n},
                   {"height", n}}}}}}};
}

TextureEvaluationOptions centreSampling() {
  TextureEvaluationOptions options;
  options.supersample = 1;  // the truth at texel centres, as the test's bitmaps are made
  return options;
}

const Trajectory kAbove = {{0, core::Isometry(Eigen::Translation3d(1.0, 1.0, 1.5))}};

TEST(TextureEvaluation, AFaithfulBitmapScoresHighAndTheTsdfBaselineIsOptional) {
  const fs::path run = test::freshTempDir();
  const json patches = writeRun(run, Eigen::Vector2d::Zero());
  const TextureEvaluation result =
      evaluateTextures(truthScene(), ".", kAbove, patches, run, core::Isometry::Identity(), nullptr,
                       centreSampling());
  ASSERT_EQ(result.patches.size(), 1u);
  EXPECT_EQ(result.patches[0].plane, "floor");
  EXPECT_EQ(result.patches[0].texels, 200u * 200u);
  EXPECT_GE(result.patches[0].psnr_db, 50.0);  // 8-bit rounding only
  EXPECT_FALSE(result.baseline_psnr_mean_db.has_value());
}

TEST(TextureEvaluation, APlacementErrorCostsPsnrThatRegistrationGivesBack) {
  const fs::path run = test::freshTempDir();
  // The bitmap shows the floor 1 cm along u and 5 mm along v from where it lies.
  const json patches = writeRun(run, Eigen::Vector2d(0.01, 0.005));
  const TextureEvaluation result =
      evaluateTextures(truthScene(), ".", kAbove, patches, run, core::Isometry::Identity(), nullptr,
                       centreSampling());
  ASSERT_EQ(result.patches.size(), 1u);
  EXPECT_LT(result.patches[0].psnr_db, 30.0);
  EXPECT_NEAR(result.patches[0].shift_m, std::hypot(0.01, 0.005), 0.001);
  EXPECT_GE(result.patches[0].registered_psnr_db, 40.0);
}

TEST(TextureEvaluation, GroundTruthWithoutTextureDefinitionsIsAClearError) {
  json truth = truthScene();
  truth["textures"][0].erase("definition_yaml");
  const fs::path run = test::freshTempDir();
  const json patches = writeRun(run, Eigen::Vector2d::Zero());
  try {
    evaluateTextures(truth, ".", kAbove, patches, run, core::Isometry::Identity(), nullptr);
    FAIL() << "expected an error";
  } catch (const core::Error& e) {
    EXPECT_NE(std::string(e.what()).find("tiles has no definition"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace tessera::eval
