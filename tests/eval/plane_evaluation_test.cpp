#include <gtest/gtest.h>

#include "tessera/eval/plane_evaluation.h"

namespace tessera::eval {
namespace {

using nlohmann::json;

// A wall 2 m in front of a camera at the origin looking along +z (n = -z, facing the camera),
// 2 m x 1.6 m, which the camera sees whole; a poster lies 5 mm in front of it.
json wallAndPosterTruth() {
  auto plane = [](const std::string& id, double z, double w, double h) {
    return json{{"id", id},
                {"normal", {0.0, 0.0, -1.0}},
                {"offset_m", -z},
                {"origin", {-w / 2, -h / 2, z}},
                {"u_axis", {1.0, 0.0, 0.0}},
                {"v_axis", {0.0, 1.0, 0.0}},
                {"polygon_uv", {{0.0, 0.0}, {w, 0.0}, {w, h}, {0.0, h}}}};
  };
  return json{{"intrinsics",
               {{"fx", 525.0},
                {"fy", 525.0},
                {"cx", 319.5},
                {"cy", 239.5},
                {"width", 640},
                {"height", 480}}},
              {"planes", {plane("wall", 2.0, 2.0, 1.6), plane("poster", 1.995, 0.6, 0.8)}}};
}

core::Trajectory onePose() { return {{0, core::Isometry::Identity()}}; }

// A patch on the plane z = z_m covering [u0, u1] x [v0, v1] in world x, y.
json patch(int id, double z_m, double u0, double u1, double v0, double v1) {
  return json{{"id", id},
              {"version", 1},
              {"normal", {0.0, 0.0, -1.0}},
              {"offset_m", -z_m},
              {"origin", {0.0, 0.0, z_m}},
              {"u_axis", {1.0, 0.0, 0.0}},
              {"v_axis", {0.0, 1.0, 0.0}},
              {"outline",
               {{{"outer", {{u0, v0}, {u1, v0}, {u1, v1}, {u0, v1}}}, {"holes", json::array()}}}}};
}

json patches(std::initializer_list<json> list) {
  return json{{"format", "tessera patches 1"}, {"patches", json(list)}};
}

TEST(PlaneEvaluation, AnExactPatchFindsThePlaneAndThePosterCountsAsPartOfIt) {
  const PlaneEvaluation result =
      evaluatePlanes(wallAndPosterTruth(), onePose(), patches({patch(0, 2.0, -1.0, 1.0, -0.8, 0.8)}),
                     core::Isometry::Identity());
  ASSERT_EQ(result.planes.size(), 1u);  // the poster is an overlay of the wall
  const PlaneResult& wall = result.planes.front();
  EXPECT_EQ(wall.id, "wall");
  EXPECT_NEAR(wall.seen_m2, 3.2, 0.1);
  EXPECT_TRUE(wall.found);
  EXPECT_GT(wall.iou, 0.97);
  EXPECT_NEAR(wall.offset_error_m, 0.0, 1e-9);
  EXPECT_DOUBLE_EQ(result.recall, 1.0);
  EXPECT_DOUBLE_EQ(result.precision, 1.0);
}

TEST(PlaneEvaluation, ADuplicatePatchCountsAgainstPrecision) {
  const PlaneEvaluation result = evaluatePlanes(
      wallAndPosterTruth(), onePose(),
      patches({patch(0, 2.0, -1.0, 1.0, -0.8, 0.8), patch(1, 2.0, -1.0, 0.0, -0.8, 0.0)}),
      core::Isometry::Identity());
  EXPECT_DOUBLE_EQ(result.recall, 1.0);
  EXPECT_DOUBLE_EQ(result.precision, 0.5);
}

// A plane cut into tiles (patches.tile_m) is one patch for the evaluation: two tiles of one
// plane that together cover the wall find it; the same halves as two planes are duplicates
// that each cover half.
TEST(PlaneEvaluation, TheTilesOfOnePlaneAreEvaluatedTogether) {
  json left = patch(0, 2.0, -1.0, 0.0, -0.8, 0.8), right = patch(1, 2.0, 0.0, 1.0, -0.8, 0.8);
  left["plane"] = 0;
  right["plane"] = 0;
  const auto tiles =
      evaluatePlanes(wallAndPosterTruth(), onePose(), patches({left, right}), core::Isometry::Identity());
  EXPECT_EQ(tiles.patches, 1u);
  EXPECT_DOUBLE_EQ(tiles.recall, 1.0);
  EXPECT_DOUBLE_EQ(tiles.precision, 1.0);
  EXPECT_GT(tiles.planes.front().iou, 0.97);

  right["plane"] = 1;
  const auto apart =
      evaluatePlanes(wallAndPosterTruth(), onePose(), patches({left, right}), core::Isometry::Identity());
  EXPECT_EQ(apart.patches, 2u);
  EXPECT_DOUBLE_EQ(apart.recall, 0.0);
  EXPECT_DOUBLE_EQ(apart.precision, 0.5);
  EXPECT_EQ(apart.duplicate_patches, 0u);  // side by side, not over one another
  EXPECT_EQ(tiles.duplicate_patches, 0u);
}

// A wall mapped twice, the second time 4 cm off after drift: the second copy covers the same
// part of the plane again and is a duplicate; the first is still the find.
TEST(PlaneEvaluation, AWallMappedTwiceAfterDriftCountsOneDuplicate) {
  const auto twice = evaluatePlanes(
      wallAndPosterTruth(), onePose(),
      patches({patch(0, 2.0, -1.0, 1.0, -0.8, 0.8), patch(1, 2.04, -0.9, 0.6, -0.8, 0.8)}),
      core::Isometry::Identity());
  EXPECT_EQ(twice.duplicate_patches, 1u);
  EXPECT_EQ(twice.planes.front().duplicates, 1);
  EXPECT_DOUBLE_EQ(twice.recall, 1.0);
  EXPECT_DOUBLE_EQ(twice.precision, 0.5);
  // Beyond the duplicate bounds (20 cm off) it is another surface, not a copy.
  const auto apart = evaluatePlanes(
      wallAndPosterTruth(), onePose(),
      patches({patch(0, 2.0, -1.0, 1.0, -0.8, 0.8), patch(1, 2.2, -0.9, 0.6, -0.8, 0.8)}),
      core::Isometry::Identity());
  EXPECT_EQ(apart.duplicate_patches, 0u);
}

TEST(PlaneEvaluation, APatchOffByTwoCentimetresOrCoveringHalfIsNotAFind) {
  const auto off =
      evaluatePlanes(wallAndPosterTruth(), onePose(), patches({patch(0, 2.02, -1.0, 1.0, -0.8, 0.8)}),
                     core::Isometry::Identity());
  EXPECT_DOUBLE_EQ(off.recall, 0.0);
  EXPECT_DOUBLE_EQ(off.precision, 0.0);
  const auto half =
      evaluatePlanes(wallAndPosterTruth(), onePose(), patches({patch(0, 2.0, -1.0, 0.0, -0.8, 0.8)}),
                     core::Isometry::Identity());
  EXPECT_DOUBLE_EQ(half.recall, 0.0);
  EXPECT_NEAR(half.planes.front().iou, 0.5, 0.03);
  EXPECT_DOUBLE_EQ(half.precision, 1.0);  // the one patch is on the wall: not a false plane
}

TEST(PlaneEvaluation, TheRunsWorldFrameIsMappedOntoTheTruthsFirst) {
  // The run's world is the truth's shifted 1 m along x: T_gt_est moves it back.
  core::Isometry T_gt_est = core::Isometry::Identity();
  T_gt_est.translation() = Eigen::Vector3d(-1.0, 0.0, 0.0);
  const auto result = evaluatePlanes(wallAndPosterTruth(), onePose(),
                                     patches({patch(0, 2.0, 0.0, 2.0, -0.8, 0.8)}), T_gt_est);
  EXPECT_DOUBLE_EQ(result.recall, 1.0);
}

TEST(PlaneEvaluation, APlaneBeyondTheDepthRangeIsNotCounted) {
  PlaneEvaluationOptions options;
  options.max_depth_m = 1.5;
  const auto result =
      evaluatePlanes(wallAndPosterTruth(), onePose(), patches({}), core::Isometry::Identity(), options);
  EXPECT_EQ(result.planes_counted, 0u);
  EXPECT_NEAR(result.planes.front().seen_m2, 0.0, 1e-12);
}

}  // namespace
}  // namespace tessera::eval
