#include <gtest/gtest.h>

#include "support/synthetic_plane.h"
#include "support/test_data.h"
#include "tessera/core/error.h"
#include "tessera/drivers/synthetic/renderer.h"
#include "tessera/planes/plane_detector.h"

namespace tessera::planes {
namespace {

namespace synthetic = drivers::synthetic;

double angleDeg(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return std::acos(std::clamp(a.normalized().dot(b.normalized()), -1.0, 1.0)) * 180.0 / M_PI;
}

TEST(PlaneDetector, FindsATiltedPlaneWithItsExactNormalAndOffset) {
  const Eigen::Vector3d n = Eigen::Vector3d(0.2, -0.3, -1.0).normalized();  // faces the camera
  const double d = n.dot(Eigen::Vector3d(0.0, 0.0, 1.8137));
  const core::Frame frame =
      test::renderPlane(test::kinectIntrinsics(), core::Isometry::Identity(), n, d);
  const PlaneDetection detection = PlaneDetector(PlaneDetectorConfig{}).detect(frame);
  ASSERT_EQ(detection.planes.size(), 1u);
  const DetectedPlane& plane = detection.planes.front();
  EXPECT_LT(angleDeg(plane.normal_C, n), 0.2);
  EXPECT_NEAR(plane.offset_C, d, 0.003);  // depth is rounded to whole millimetres
  EXPECT_LT(plane.rms_residual_m, 0.002);
  // The plane fills the view: nearly every working pixel is labelled with it.
  EXPECT_GT(static_cast<double>(plane.pixels), 0.9 * static_cast<double>(detection.labels.total()));
  EXPECT_EQ(detection.labels.cols, 320);
}

TEST(PlaneDetector, NoValidDepthGivesNoPlane) {
  core::Frame frame = test::renderPlane(test::kinectIntrinsics(), core::Isometry::Identity(),
                                        Eigen::Vector3d(0, 0, -1), -1.5);
  frame.depth_mm.setTo(0);
  const PlaneDetection detection = PlaneDetector(PlaneDetectorConfig{}).detect(frame);
  EXPECT_TRUE(detection.planes.empty());
  EXPECT_EQ(cv::countNonZero(detection.labels != PlaneDetection::kNoPlane), 0);
}

TEST(PlaneDetector, FrameWhoseSizeDisagreesWithItsIntrinsicsIsRejected) {
  core::Frame frame = test::renderPlane(test::kinectIntrinsics(), core::Isometry::Identity(),
                                        Eigen::Vector3d(0, 0, -1), -1.5);
  frame.intrinsics.width = 320;
  EXPECT_THROW(PlaneDetector(PlaneDetectorConfig{}).detect(frame), core::Error);
}

// Every plane found in noisy Kinect v1 frames of the office is one of the scene's planes,
// within the bounds (normal within 2 degrees, offset within 1 cm), and each frame shows
// at least two of them. Two parallel faces 10 cm apart at 2.9 m (frame 80) must not become one.
TEST(PlaneDetector, PlanesOfTheNoisyOfficeMatchTheSceneGroundTruth) {
  const synthetic::Scene scene =
      synthetic::loadScene(test::sourceDir() / "config/scenes/office.yaml");
  const PlaneDetector detector(PlaneDetectorConfig{});
  for (const int i : {0, 80, 160, 240}) {
    SCOPED_TRACE(i);
    core::Frame frame;
    frame.intrinsics = scene.sensor.intrinsics;
    const core::Isometry T_W_C = scene.cameraPose(i);
    const auto view = synthetic::renderClean(scene, frame.intrinsics, T_W_C, 1);
    synthetic::applySensor(scene.sensor, view, static_cast<std::uint64_t>(i), frame.depth_mm,
                           frame.rgb);
    const PlaneDetection detection = detector.detect(frame);
    EXPECT_GE(detection.planes.size(), 2u);  // at least the floor and a wall
    for (const DetectedPlane& plane : detection.planes) {
      const Eigen::Vector3d n_W = T_W_C.linear() * plane.normal_C;
      const Eigen::Vector3d centroid_W = T_W_C * plane.centroid_C;
      double best_angle = 180.0, best_offset = 0.0;
      for (const auto& truth : scene.planes) {
        // The scene's normal may face either way; compare lines, not directions.
        const double sign = truth.normal.dot(n_W) < 0.0 ? -1.0 : 1.0;
        const double angle = angleDeg(sign * truth.normal, n_W);
        // The region's centroid distance to the scene plane (a plane offset would magnify a
        // small tilt by the distance from the world origin).
        const double offset = std::abs(truth.normal.dot(centroid_W) - truth.offset());
        if (offset < 0.05 && angle < best_angle) best_angle = angle, best_offset = offset;
      }
      EXPECT_LT(best_angle, 2.0) << plane.pixels << " pixels at " << plane.centroid_C.transpose();
      EXPECT_LT(best_offset, 0.01) << plane.pixels << " pixels, n_W " << n_W.transpose();
    }
  }
}

}  // namespace
}  // namespace tessera::planes
