// What reuses cost the view (reuse_cost.h), from an evaluation whose figures are known: the
// overall losses are the unmatched map's means minus the run's, and each patch stored through
// another texture gets the PSNR of its own surfaces and its overlays', in both maps.
#include "tessera/eval/reuse_cost.h"

#include <cmath>

#include <gtest/gtest.h>

namespace tessera::eval {
namespace {

ImageSimilarity similarity(double psnr_db, double ssim, double detail) {
  ImageSimilarity s;
  s.psnr_db = psnr_db;
  s.ssim = ssim;
  s.detail = detail;
  return s;
}

// The squared error (over R, G and B) that gives `psnr_db` over `pixels` pixels.
double squaredErrorFor(double psnr_db, std::size_t pixels) {
  return 3.0 * static_cast<double>(pixels) * 255.0 * 255.0 / std::pow(10.0, psnr_db / 10.0);
}

TEST(ReuseCost, OverallLossesAndOnePerPatchStoredThroughAnotherTexture) {
  ViewEvaluation evaluation;
  evaluation.models = {"patches", "mesh", "unmatched"};
  // Two training views and one held-out view.
  for (const auto& [held_out, run, unmatched] :
       {std::tuple{false, 30.0, 31.0}, std::tuple{false, 28.0, 29.0},
        std::tuple{true, 26.0, 26.5}}) {
    ViewScore view;
    view.held_out = held_out;
    view.similarity = {similarity(run, 0.80, 0.30), similarity(20.0, 0.5, 0.1),
                       similarity(unmatched, 0.85, 0.40)};
    evaluation.views.push_back(view);
  }
  // Patch 3 (a reuse with an overlay): its object 100 pixels, its overlay 300; both at 30 dB
  // in the run, 36 dB unmatched. Patch 4 is stored as its own bitmap; patch 7 is a pattern no
  // training view saw; "floor" is not a patch's object.
  const auto surface = [](const char* name, std::size_t pixels, double run, double unmatched) {
    return SurfaceError{
        name, pixels, {squaredErrorFor(run, pixels), 0.0, squaredErrorFor(unmatched, pixels)}};
  };
  evaluation.surfaces = {surface("patch_3_v2", 100, 30.0, 36.0),
                         surface("patch_3_v2_overlay_0", 300, 30.0, 36.0),
                         surface("patch_4_v1", 500, 25.0, 25.0), surface("floor", 50, 10.0, 40.0),
                         surface("patch_7_v1", 0, 0.0, 0.0)};
  const nlohmann::json patches = {
      {"patches",
       {{{"id", 3},
         {"version", 2},
         {"instance",
          {{"reused", true},
           {"tiled", false},
           {"texture_id", 11},
           {"overlays", nlohmann::json::array({nlohmann::json::object()})}}}},
        {{"id", 4},
         {"version", 1},
         {"instance",
          {{"reused", false},
           {"tiled", false},
           {"texture_id", 12},
           {"overlays", nlohmann::json::array()}}}},
        {{"id", 7},
         {"version", 1},
         {"instance",
          {{"reused", false},
           {"tiled", true},
           {"texture_id", 13},
           {"overlays", nlohmann::json::array()}}}}}}};

  const nlohmann::json figures = reuseCostFigures(evaluation, 2, patches);
  EXPECT_NEAR(figures["view_psnr_lost_db"].get<double>(), 1.0, 1e-9);
  EXPECT_NEAR(figures["view_psnr_lost_holdout_db"].get<double>(), 0.5, 1e-9);
  EXPECT_NEAR(figures["view_ssim_lost"].get<double>(), 0.05, 1e-9);
  EXPECT_NEAR(figures["view_detail_lost"].get<double>(), 0.10, 1e-9);
  const nlohmann::json& costs = figures["view_reuse_costs"];
  ASSERT_EQ(costs.size(), 1u) << costs.dump();
  EXPECT_EQ(costs[0]["patch"], 3);
  EXPECT_EQ(costs[0]["version"], 2);
  EXPECT_EQ(costs[0]["stored_as"], "reuse+layers");
  EXPECT_EQ(costs[0]["texture_id"], 11);
  EXPECT_EQ(costs[0]["pixels"], 400u);
  EXPECT_NEAR(costs[0]["psnr_db"].get<double>(), 30.0, 1e-9);
  EXPECT_NEAR(costs[0]["unmatched_psnr_db"].get<double>(), 36.0, 1e-9);
  EXPECT_NEAR(costs[0]["psnr_lost_db"].get<double>(), 6.0, 1e-9);
}

TEST(ReuseCost, NoViewsOfAKindGiveNullLosses) {
  ViewEvaluation evaluation;
  evaluation.models = {"patches", "mesh", "unmatched"};
  ViewScore view;
  view.similarity = {similarity(30.0, 0.8, 0.3), similarity(20.0, 0.5, 0.1),
                     similarity(29.0, 0.8, 0.3)};
  evaluation.views.push_back(view);
  const nlohmann::json figures = reuseCostFigures(evaluation, 2, nlohmann::json::object());
  EXPECT_NEAR(figures["view_psnr_lost_db"].get<double>(), -1.0, 1e-9);  // a gain
  EXPECT_TRUE(figures["view_psnr_lost_holdout_db"].is_null());
  EXPECT_TRUE(figures["view_reuse_costs"].empty());
}

}  // namespace
}  // namespace tessera::eval
