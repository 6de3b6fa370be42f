#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include "tessera/planes/plane_alignment.h"

namespace tessera::planes {
namespace {

// The correction is off by default (it adds error to the keyframe tracker); these tests switch
// it on.
PlaneAlignmentConfig enabled() {
  PlaneAlignmentConfig config;
  config.enabled = true;
  return config;
}

// Points 2 cm apart over a width x height rectangle from `origin` along u and v.
PlaneObservation rectangle(const Eigen::Vector3d& origin, const Eigen::Vector3d& u,
                           const Eigen::Vector3d& v, double width, double height) {
  PlaneObservation observation;
  for (double a = 0.0; a <= width; a += 0.02) {
    for (double b = 0.0; b <= height; b += 0.02)
      observation.points_W.push_back(origin + a * u + b * v);
  }
  return observation;
}

// A room corner: floor z = 0, walls x = 0 and y = 0, each 2 m wide.
std::vector<PlaneObservation> corner() {
  const Eigen::Vector3d x = Eigen::Vector3d::UnitX(), y = Eigen::Vector3d::UnitY(),
                        z = Eigen::Vector3d::UnitZ();
  return {rectangle(Eigen::Vector3d(0.1, 0.1, 0), x, y, 2, 2),
          rectangle(Eigen::Vector3d(0, 0.1, 0.1), y, z, 2, 2),
          rectangle(Eigen::Vector3d(0.1, 0, 0.1), x, z, 2, 2)};
}

PatchMap establishedMap(const std::vector<PlaneObservation>& observations) {
  PatchMap map(PatchMapConfig{});
  for (long frame = 0; frame < 20; ++frame) {
    map.add(observations);
    map.endFrame(frame);
  }
  return map;
}

std::vector<PlaneObservation> moved(std::vector<PlaneObservation> observations,
                                    const core::Isometry& M) {
  for (auto& observation : observations) {
    for (auto& X : observation.points_W) X = M * X;
  }
  return observations;
}

// Drift of 1.5 cm and 0.8 degrees about the camera.
core::Isometry drift(const Eigen::Vector3d& camera) {
  core::Isometry about = core::Isometry::Identity();
  about.translation() = camera;
  core::Isometry M = core::Isometry::Identity();
  M.linear() = Eigen::AngleAxisd(0.8 * M_PI / 180, Eigen::Vector3d(0.3, -0.5, 1).normalized())
                   .toRotationMatrix();
  M.translation() = Eigen::Vector3d(0.01, -0.008, 0.007);
  return about * M * about.inverse();
}

TEST(PlaneAlignment, ThreeWallsOfACornerUndoTheDriftOfAFrame) {
  const PatchMap map = establishedMap(corner());
  const Eigen::Vector3d camera(1.5, 1.5, 1.4);
  const core::Isometry M = drift(camera);
  const auto D = alignToPatches(map, moved(corner(), M), camera, enabled());
  ASSERT_TRUE(D.has_value());
  const core::Isometry residual = *D * M;
  EXPECT_LT(Eigen::AngleAxisd(residual.linear()).angle() * 180 / M_PI, 0.02);
  // The residual moves points near the corner by well under a millimetre.
  EXPECT_LT((residual * Eigen::Vector3d(1, 1, 1) - Eigen::Vector3d(1, 1, 1)).norm(), 5e-4);
}

TEST(PlaneAlignment, OneFloorCorrectsOnlyHeightAndTiltNeverSlidesAlongIt) {
  const std::vector<PlaneObservation> floor = {corner().front()};
  const PatchMap map = establishedMap(floor);
  const Eigen::Vector3d camera(1.0, 1.0, 1.4);
  core::Isometry M = core::Isometry::Identity();
  M.translation() = Eigen::Vector3d(0.02, 0.01, 0.015);  // slides along the floor and lifts it
  const auto D = alignToPatches(map, moved(floor, M), camera, enabled());
  ASSERT_TRUE(D.has_value());
  EXPECT_NEAR(D->translation().z(), -0.015, 1e-4);
  EXPECT_NEAR(D->translation().x(), 0.0, 1e-4);  // unconstrained: left alone
  EXPECT_NEAR(D->translation().y(), 0.0, 1e-4);
}

TEST(PlaneAlignment, NoEstablishedPatchOrATooLargeStepGivesNoCorrection) {
  PatchMap young(PatchMapConfig{});
  young.add(corner());
  young.endFrame(0);
  const Eigen::Vector3d camera(1.5, 1.5, 1.4);
  EXPECT_FALSE(alignToPatches(young, corner(), camera, enabled()).has_value());

  const PatchMap map = establishedMap(corner());
  core::Isometry far = core::Isometry::Identity();
  far.translation() = Eigen::Vector3d(0.0, 0.0, 0.025);  // within association, beyond max_step
  PlaneAlignmentConfig strict = enabled();
  strict.max_step_m = 0.01;
  EXPECT_FALSE(alignToPatches(map, moved(corner(), far), camera, strict).has_value());
  EXPECT_TRUE(alignToPatches(map, moved(corner(), far), camera, enabled()).has_value());
}

}  // namespace
}  // namespace tessera::planes
