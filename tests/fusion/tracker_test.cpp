#include <gtest/gtest.h>

#include "support/test_data.h"
#include "tessera/drivers/synthetic/renderer.h"
#include "tessera/fusion/tracker.h"

namespace tessera::fusion {
namespace {

namespace synthetic = drivers::synthetic;

// Frame i of the office scene, rendered through the Kinect v1 model.
core::Frame officeFrame(const synthetic::Scene& scene, int i) {
  core::Frame frame;
  frame.index = static_cast<std::uint64_t>(i);
  frame.intrinsics = scene.sensor.intrinsics;
  frame.T_W_C_gt = scene.cameraPose(i);
  const auto view = synthetic::renderClean(scene, frame.intrinsics, *frame.T_W_C_gt, 1);
  synthetic::applySensor(scene.sensor, view, static_cast<std::uint64_t>(i), frame.depth_mm,
                         frame.rgb);
  return frame;
}

double translationError(const core::Isometry& a, const core::Isometry& b) {
  return (a.translation() - b.translation()).norm();
}

TEST(Tracker, FollowsTheSyntheticOfficeWithinAFewMillimetres) {
  const synthetic::Scene scene =
      synthetic::loadScene(test::sourceDir() / "config/scenes/office.yaml");
  Tracker tracker(TrackerConfig{});
  double worst = 0.0;
  for (int i = 0; i < 12; ++i) {
    const core::Frame frame = officeFrame(scene, i);
    const TrackingResult result = tracker.track(frame, *frame.T_W_C_gt);
    ASSERT_NE(result.status, TrackingStatus::kLost) << "frame " << i << ": " << result.problem;
    worst = std::max(worst, translationError(result.T_W_C, *frame.T_W_C_gt));
  }
  EXPECT_LT(worst, 0.01);  // 12 frames of drift from the first, true pose
}

TEST(Tracker, ASuddenJumpIsALossAndTrackingGoesOnFromTheLastGoodFrame) {
  const synthetic::Scene scene =
      synthetic::loadScene(test::sourceDir() / "config/scenes/office.yaml");
  Tracker tracker(TrackerConfig{});
  for (int i = 0; i < 3; ++i) {
    const core::Frame frame = officeFrame(scene, i);
    ASSERT_NE(tracker.track(frame, *frame.T_W_C_gt).status, TrackingStatus::kLost);
  }
  // Frame 120 is metres and tens of degrees away: beyond any per-frame bound.
  const TrackingResult jump = tracker.track(officeFrame(scene, 120), core::Isometry::Identity());
  EXPECT_EQ(jump.status, TrackingStatus::kLost);
  EXPECT_FALSE(jump.problem.empty());
  // The next frame in sequence tracks again against the last good one.
  const core::Frame next = officeFrame(scene, 3);
  const TrackingResult again = tracker.track(next, core::Isometry::Identity());
  EXPECT_EQ(again.status, TrackingStatus::kTracked);
  EXPECT_LT(translationError(again.T_W_C, *next.T_W_C_gt), 0.01);
}

TEST(Tracker, AFrameWithNoValidDepthIsALoss) {
  const synthetic::Scene scene =
      synthetic::loadScene(test::sourceDir() / "config/scenes/office.yaml");
  Tracker tracker(TrackerConfig{});
  const core::Frame first = officeFrame(scene, 0);
  tracker.track(first, *first.T_W_C_gt);
  core::Frame empty = officeFrame(scene, 1);
  empty.depth_mm.setTo(0);
  EXPECT_EQ(tracker.track(empty, core::Isometry::Identity()).status, TrackingStatus::kLost);
}

}  // namespace
}  // namespace tessera::fusion
