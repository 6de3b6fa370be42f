#include <gtest/gtest.h>

#include "tessera/core/pose.h"

namespace tessera::core {
namespace {

TEST(Pose, QuaternionOrderIsXyzw) {
  // 90 degrees about z: x axis goes to y.
  const double s = std::sqrt(0.5);
  const Isometry T = isometryFromTranslationQuaternion({1, 2, 3}, 0, 0, s, s);
  const Eigen::Vector3d x = T.linear() * Eigen::Vector3d::UnitX();
  EXPECT_NEAR((x - Eigen::Vector3d::UnitY()).norm(), 0.0, 1e-12);
  EXPECT_NEAR((T * Eigen::Vector3d::Zero() - Eigen::Vector3d(1, 2, 3)).norm(), 0.0, 1e-12);
}

TEST(Pose, InterpolatesTranslationLinearlyAndRotationBySlerp) {
  const Isometry a = isometryFromTranslationQuaternion({0, 0, 0}, 0, 0, 0, 1);
  const double half = std::sqrt(0.5);
  const Isometry b = isometryFromTranslationQuaternion({2, 0, 0}, 0, 0, half, half);  // 90 deg
  const Isometry mid = interpolate(a, b, 0.5);
  EXPECT_NEAR(mid.translation().x(), 1.0, 1e-12);
  const Eigen::AngleAxisd angle(mid.rotation());
  EXPECT_NEAR(angle.angle(), M_PI / 4, 1e-12);
  EXPECT_TRUE(interpolate(a, b, 1.0).isApprox(b, 1e-12));
}

TEST(Pose, PosesAreNearWithinBothBoundsWhereverTheyAre) {
  // A camera far from the origin and turned: nearness is measured between the two poses.
  core::Isometry a =
      isometryFromTranslationQuaternion({5, -3, 2}, 0, std::sin(0.3), 0, std::cos(0.3));
  core::Isometry b = a;
  b.translate(Eigen::Vector3d(0.0, 0.0, 0.2));                                 // 20 cm ahead
  b.rotate(Eigen::AngleAxisd(10.0 * M_PI / 180.0, Eigen::Vector3d::UnitY()));  // 10 degrees
  EXPECT_TRUE(posesNear(a, b, 0.21, 10.5));
  EXPECT_TRUE(posesNear(b, a, 0.21, 10.5));
  EXPECT_FALSE(posesNear(a, b, 0.19, 10.5));  // too far
  EXPECT_FALSE(posesNear(a, b, 0.21, 9.5));   // turned too far
}

}  // namespace
}  // namespace tessera::core
