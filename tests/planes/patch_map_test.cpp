#include <random>

#include <gtest/gtest.h>

#include "support/synthetic_plane.h"
#include "tessera/planes/patch_map.h"

namespace tessera::planes {
namespace {

// Points on the plane z = height + tilt * x over [x0, x1] x [y0, y1], 1 cm apart, with
// seeded Gaussian noise of sigma_m along z.
PlaneObservation strip(double x0, double x1, double y0, double y1, double height,
                       double sigma_m = 0.0, double tilt = 0.0, unsigned seed = 1) {
  std::mt19937 random(seed);
  std::normal_distribution<double> noise(0.0, sigma_m);
  PlaneObservation observation;
  for (double x = x0; x <= x1; x += 0.01) {
    for (double y = y0; y <= y1; y += 0.01) {
      observation.points_W.emplace_back(x, y,
                                        height + tilt * x + (sigma_m > 0 ? noise(random) : 0.0));
    }
  }
  return observation;
}

TEST(PatchMap, TheSamePlaneSeenAgainGrowsOnePatch) {
  PatchMap map(PatchMapConfig{});
  map.add({strip(0.0, 1.0, 0.0, 1.0, 0.75, 0.005, 0.0, 1)});
  map.add({strip(0.8, 1.8, 0.0, 1.0, 0.75, 0.005, 0.0, 2)});  // overlaps and extends it
  ASSERT_EQ(map.patches().size(), 1u);
  const Patch& patch = map.patches().front();
  EXPECT_NEAR(std::abs(patch.normal.z()), 1.0, 1e-4);
  EXPECT_NEAR(std::abs(patch.offset), 0.75, 0.002);
  EXPECT_NEAR(map.areaM2(patch), 1.8, 0.2);  // 1.8 m x 1 m, to within the cell size
}

TEST(PatchMap, ParallelPlanesTenCentimetresApartStaySeparate) {
  PatchMap map(PatchMapConfig{});
  const std::vector<int> ids =
      map.add({strip(0.0, 1.0, 0.0, 1.0, 0.70), strip(0.0, 1.0, 0.0, 1.0, 0.80)});
  EXPECT_EQ(map.patches().size(), 2u);
  EXPECT_NE(ids[0], ids[1]);
}

TEST(PatchMap, APlaneTiltedBeyondTheAngleBoundIsANewPatch) {
  PatchMap map(PatchMapConfig{});
  map.add({strip(0.0, 1.0, 0.0, 1.0, 0.75)});
  map.add({strip(0.9, 1.9, 0.0, 1.0, 0.75 - 0.9 * 0.2, 0.0, 0.2)});  // 11 degrees, touching
  EXPECT_EQ(map.patches().size(), 2u);
}

TEST(PatchMap, TwoDisjointPartsThatLaterJoinBecomeOnePatch) {
  // A table seen first at its two ends (say, behind a vase), then whole.
  PatchMap map(PatchMapConfig{});
  const auto left = map.add({strip(0.0, 0.6, 0.0, 0.8, 0.75)});
  const auto right = map.add({strip(1.4, 2.0, 0.0, 0.8, 0.75)});
  ASSERT_EQ(map.patches().size(), 2u);
  ASSERT_NE(left[0], right[0]);
  const auto whole = map.add({strip(0.5, 1.5, 0.0, 0.8, 0.75)});
  ASSERT_EQ(map.patches().size(), 1u);
  EXPECT_EQ(whole[0], std::min(left[0], right[0]));  // the older patch is kept
  EXPECT_NEAR(map.areaM2(map.patches().front()), 2.0 * 0.8, 0.2);
  EXPECT_NEAR(std::abs(map.patches().front().offset), 0.75, 1e-6);
}

TEST(PatchMap, RegionsOfARenderedPlaneBecomeWorldPoints) {
  const Eigen::Vector3d n = Eigen::Vector3d(0.1, -0.2, -1.0).normalized();
  core::Isometry T_W_C = core::Isometry::Identity();
  T_W_C.translation() = Eigen::Vector3d(0.3, -0.1, 0.2);
  const double d = n.dot(Eigen::Vector3d(0.0, 0.0, 2.0));
  const core::Frame frame = test::renderPlane(test::kinectIntrinsics(), T_W_C, n, d);
  const PlaneDetection detection = PlaneDetector(PlaneDetectorConfig{}).detect(frame);
  const auto observations = observationsOf(frame, detection, T_W_C);
  ASSERT_EQ(observations.size(), 1u);
  ASSERT_GT(observations[0].points_W.size(), 50000u);
  double worst = 0.0;
  for (const auto& X : observations[0].points_W) worst = std::max(worst, std::abs(n.dot(X) - d));
  EXPECT_LT(worst, 0.003);  // millimetre depth rounding at about 2 m
}

}  // namespace
}  // namespace tessera::planes
