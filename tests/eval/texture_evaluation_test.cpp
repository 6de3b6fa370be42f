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
json tiledFloorTruth() {
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

constexpr double kTexelM = 0.005;

// An n x n image (BGRA, opaque) of a texture sampled at the centres of 5 mm texels whose first
// one starts at `origin` (metres, texture coordinates).
cv::Mat sampled(const char* definition_yaml, const Eigen::Vector2d& origin, int n) {
  const core::ConfigDocument definition = core::ConfigDocument::fromString(definition_yaml, "test");
  const auto texture = drivers::synthetic::makeTexture(definition.root(), ".");
  cv::Mat bgra(n, n, CV_8UC4);
  for (int r = 0; r < n; ++r) {
    for (int c = 0; c < n; ++c) {
      const cv::Vec3f rgb =
          texture->colour(origin.x() + (c + 0.5) * kTexelM, origin.y() + (r + 0.5) * kTexelM);
      bgra.at<cv::Vec4b>(r, c) = cv::Vec4b(cv::saturate_cast<std::uint8_t>(rgb[2]),
                                           cv::saturate_cast<std::uint8_t>(rgb[1]),
                                           cv::saturate_cast<std::uint8_t>(rgb[0]), 255);
    }
  }
  return bgra;
}

// Patch `id` of a run: an n x n grid of 5 mm texels over the floor from `origin_uv`, its bitmap
// the true texture at each texel centre moved by `error` (metres, in the plane), all observed.
json writePatch(const fs::path& run_dir, int id, const Eigen::Vector2d& origin_uv, int n,
                const Eigen::Vector2d& error = Eigen::Vector2d::Zero()) {
  const std::string image = "textures/patch_" + std::to_string(id) + ".png";
  const std::string state_image = "textures/patch_" + std::to_string(id) + "_state.png";
  fs::create_directories(run_dir / "textures");
  cv::imwrite((run_dir / image).string(), sampled(kTiles, origin_uv + error, n));
  cv::imwrite((run_dir / state_image).string(), cv::Mat(n, n, CV_8UC1, cv::Scalar(255)));
  return json{{"id", id},
              {"origin", {0.0, 0.0, 0.0}},
              {"u_axis", {1.0, 0.0, 0.0}},
              {"v_axis", {0.0, 1.0, 0.0}},
              {"texture",
               {{"image", image},
                {"state_image", state_image},
                {"texel_m", kTexelM},
                {"origin_uv", {origin_uv.x(), origin_uv.y()}},
                {"x_axis", {1.0, 0.0}},
                {"y_axis", {0.0, 1.0}},
                {"width", n},
                {"height", n}}},
              {"instance", nullptr}};
}

// A run whose one patch covers [0.5, 1.5]^2 of the floor with 5 mm texels, its bitmap the
// true texture at each texel centre moved by `error` (metres, in the plane).
json writeRun(const fs::path& run_dir, const Eigen::Vector2d& error) {
  return json{{"patches", {writePatch(run_dir, 1, {0.5, 0.5}, 200, error)}}};
}

// Gives `patch` the database texture `texture_id` (textures/texture_<id>.png, written from
// `bgra` when given) through patch texel -> texture pixel translation (tx, ty).
void setInstance(json& patch, const fs::path& run_dir, std::int64_t texture_id, bool reused,
                 double tx = 0.0, double ty = 0.0, const cv::Mat& bgra = cv::Mat()) {
  const std::string image = "textures/texture_" + std::to_string(texture_id) + ".png";
  if (!bgra.empty()) cv::imwrite((run_dir / image).string(), bgra);
  const cv::Mat written = cv::imread((run_dir / image).string(), cv::IMREAD_UNCHANGED);
  patch["instance"] = {{"texture_id", texture_id},
                       {"image", image},
                       {"width", written.cols},
                       {"height", written.rows},
                       {"transform", {1.0, 0.0, tx, ty}},
                       {"tiled", false},
                       {"reused", reused},
                       {"psnr_db", reused ? json(40.0) : json(nullptr)}};
}

// Patch 1 over [0.2, 1.0]^2 of the floor stores its bitmap as texture 1; patch 2 over
// [0.8, 1.6] x [0.2, 1.0], one period of the tiles further along u, shows the same texels.
struct TwoPatchRun {
  fs::path dir;
  json patches;
};
TwoPatchRun twoPatchRun() {
  TwoPatchRun run{test::freshTempDir(), json::object()};
  json first = writePatch(run.dir, 1, {0.2, 0.2}, 160);
  json second = writePatch(run.dir, 2, {0.8, 0.2}, 160);
  const cv::Mat first_bitmap =
      cv::imread((run.dir / "textures/patch_1.png").string(), cv::IMREAD_UNCHANGED);
  setInstance(first, run.dir, 1, /*reused=*/false, 0.0, 0.0, first_bitmap);
  run.patches = json{{"patches", {first, second}}};
  return run;
}

const PatchTextureResult& patchResult(const TextureEvaluation& evaluation, int id) {
  for (const PatchTextureResult& p : evaluation.patches) {
    if (p.patch_id == id) return p;
  }
  throw std::runtime_error("patch " + std::to_string(id) + " not evaluated");
}

TextureEvaluationOptions centreSampling() {
  TextureEvaluationOptions options;
  options.supersample = 1;  // the truth at texel centres, as the test's bitmaps are made
  return options;
}

const core::Trajectory kAbove = {{0, core::Isometry(Eigen::Translation3d(1.0, 1.0, 1.5))}};

TEST(TextureEvaluation, AFaithfulBitmapScoresHighAndTheTsdfBaselineIsOptional) {
  const fs::path run = test::freshTempDir();
  const json patches = writeRun(run, Eigen::Vector2d::Zero());
  const TextureEvaluation result =
      evaluateTextures(tiledFloorTruth(), ".", kAbove, patches, run, core::Isometry::Identity(), nullptr,
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
      evaluateTextures(tiledFloorTruth(), ".", kAbove, patches, run, core::Isometry::Identity(), nullptr,
                       centreSampling());
  ASSERT_EQ(result.patches.size(), 1u);
  EXPECT_LT(result.patches[0].psnr_db, 30.0);
  EXPECT_NEAR(result.patches[0].shift_m, std::hypot(0.01, 0.005), 0.001);
  EXPECT_GE(result.patches[0].registered_psnr_db, 40.0);
}

TEST(TextureEvaluation, AReuseOfTheSameTrueTexturePlacedRightIsNotAFalseMatch) {
  TwoPatchRun run = twoPatchRun();
  setInstance(run.patches["patches"][1], run.dir, 1, /*reused=*/true);  // identity: exact
  const TextureEvaluation result =
      evaluateTextures(tiledFloorTruth(), ".", kAbove, run.patches, run.dir, core::Isometry::Identity(),
                       nullptr, centreSampling());
  ASSERT_EQ(result.patches.size(), 2u);
  const PatchTextureResult& stored = patchResult(result, 1);
  EXPECT_FALSE(stored.reused);
  EXPECT_EQ(stored.texture_id, 1);
  EXPECT_FALSE(stored.false_match);
  EXPECT_FALSE(stored.missed_match);
  EXPECT_FALSE(stored.reuse_psnr_db.has_value());
  const PatchTextureResult& reuse = patchResult(result, 2);
  EXPECT_TRUE(reuse.reused);
  EXPECT_EQ(reuse.texture_id, 1);
  EXPECT_EQ(reuse.true_texture, "tiles");
  EXPECT_EQ(reuse.reuse_texels, 160u * 160u);
  ASSERT_TRUE(reuse.reuse_psnr_db.has_value());
  EXPECT_GE(*reuse.reuse_psnr_db, 50.0);
  ASSERT_TRUE(reuse.reuse_shift_texels.has_value());
  EXPECT_LT(*reuse.reuse_shift_texels, 0.5);
  EXPECT_FALSE(reuse.false_match);
  EXPECT_EQ(result.reuses, 1u);
  EXPECT_EQ(result.false_matches, 0u);
  EXPECT_EQ(result.false_match_rate, 0.0);
  EXPECT_EQ(result.missed_match_rate, 0.0);  // 0 missed of 1 chance, taken
  // The tiles repeat every 0.6 m: one 120 x 120 texel cell is all the map needs.
  ASSERT_TRUE(result.ideal_pixels.has_value());
  EXPECT_NEAR(*result.ideal_pixels, 120.0 * 120.0, 1e-6);
}

TEST(TextureEvaluation, AReuseFiveTexelsOffIsAFalseMatch) {
  TwoPatchRun run = twoPatchRun();
  // Patch texel (c, r) shows texture pixel (c + 5, r): the truth 2.5 cm along u.
  setInstance(run.patches["patches"][1], run.dir, 1, /*reused=*/true, 5.0, 0.0);
  const TextureEvaluation result =
      evaluateTextures(tiledFloorTruth(), ".", kAbove, run.patches, run.dir, core::Isometry::Identity(),
                       nullptr, centreSampling());
  const PatchTextureResult& reuse = patchResult(result, 2);
  ASSERT_TRUE(reuse.reuse_shift_texels.has_value());
  EXPECT_NEAR(*reuse.reuse_shift_texels, 5.0, 0.5);
  // Registered, it is as faithful as the patch's own bitmap: only the shift makes it false.
  ASSERT_TRUE(reuse.reuse_registered_psnr_db.has_value());
  EXPECT_GT(*reuse.reuse_registered_psnr_db, reuse.registered_psnr_db - 6.0);
  EXPECT_TRUE(reuse.false_match);
  EXPECT_EQ(result.false_matches, 1u);
  EXPECT_EQ(result.false_match_rate, 1.0);
  EXPECT_FALSE(result.missed_match_rate.has_value());  // no chance to reuse was taken or missed
}

TEST(TextureEvaluation, AReuseOfAnotherTextureIsAFalseMatch) {
  TwoPatchRun run = twoPatchRun();
  // Texture 7: cobblestones, which no plane of the truth shows.
  const char* cobbles = "{id: cobbles, generator: cobblestone, seed: 5, period_m: 0.4}";
  setInstance(run.patches["patches"][1], run.dir, 7, /*reused=*/true, 0.0, 0.0,
              sampled(cobbles, Eigen::Vector2d::Zero(), 160));
  const TextureEvaluation result =
      evaluateTextures(tiledFloorTruth(), ".", kAbove, run.patches, run.dir, core::Isometry::Identity(),
                       nullptr, centreSampling());
  const PatchTextureResult& reuse = patchResult(result, 2);
  EXPECT_EQ(reuse.texture_id, 7);
  ASSERT_TRUE(reuse.reuse_registered_psnr_db.has_value());
  EXPECT_LT(*reuse.reuse_registered_psnr_db, reuse.registered_psnr_db - 6.0);
  EXPECT_TRUE(reuse.false_match);
  EXPECT_EQ(result.false_match_rate, 1.0);
}

TEST(TextureEvaluation, StoringAnAlreadyStoredTrueTextureAgainIsAMissedMatch) {
  TwoPatchRun run = twoPatchRun();
  // Patch 2 stores its own bitmap too, as texture 3; patch 1's texture 1 came first.
  json& second = run.patches["patches"][1];
  setInstance(second, run.dir, 3, /*reused=*/false, 0.0, 0.0,
              cv::imread((run.dir / "textures/patch_2.png").string(), cv::IMREAD_UNCHANGED));
  // A third patch, stored before both (texture id 0) and on the same tiles, makes patch 1 the
  // second one stored: commit order is texture id order, not patch order.
  json third = writePatch(run.dir, 3, {0.2, 1.0}, 100);
  setInstance(third, run.dir, 0, /*reused=*/false, 0.0, 0.0,
              cv::imread((run.dir / "textures/patch_3.png").string(), cv::IMREAD_UNCHANGED));
  run.patches["patches"].push_back(third);
  const TextureEvaluation result =
      evaluateTextures(tiledFloorTruth(), ".", kAbove, run.patches, run.dir, core::Isometry::Identity(),
                       nullptr, centreSampling());
  ASSERT_EQ(result.patches.size(), 3u);
  EXPECT_FALSE(patchResult(result, 3).missed_match);
  EXPECT_TRUE(patchResult(result, 1).missed_match);
  EXPECT_TRUE(patchResult(result, 2).missed_match);
  EXPECT_EQ(result.stored, 3u);
  EXPECT_EQ(result.missed_matches, 2u);
  EXPECT_EQ(result.reuses, 0u);
  EXPECT_FALSE(result.false_match_rate.has_value());
  EXPECT_EQ(result.missed_match_rate, 1.0);
}

TEST(TextureEvaluation, GroundTruthWithoutTextureDefinitionsIsAClearError) {
  json truth = tiledFloorTruth();
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
