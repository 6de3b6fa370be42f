#include <cmath>

#include <gtest/gtest.h>

#include "support/synthetic_office.h"
#include "support/test_data.h"
#include "tessera/core/registration.h"
#include "tessera/core/trajectory.h"
#include "tessera/drivers/dataset_source.h"
#include "tessera/fusion/tracker.h"
#include "tessera/planes/plane_detector.h"

namespace tessera::fusion {
namespace {

namespace synthetic = drivers::synthetic;

using test::moved;
using test::officeFrame;
using test::officeFrameAt;
using test::rotationErrorDeg;

struct PathErrors {
  double worst_m = 0.0;
  double worst_deg = 0.0;
  core::Isometry last = core::Isometry::Identity();
};

// Tracks the office along `poses`, from the true first pose; every frame must track.
PathErrors trackPath(const synthetic::Scene& scene, const std::vector<core::Isometry>& poses) {
  Tracker tracker(TrackerConfig{});
  PathErrors errors;
  for (std::size_t i = 0; i < poses.size(); ++i) {
    const core::Frame frame = officeFrameAt(scene, poses[i], static_cast<int>(i));
    const TrackingResult result = tracker.track(frame, poses.front());
    EXPECT_NE(result.status, TrackingStatus::kLost) << "frame " << i << ": " << result.problem;
    errors.worst_m =
        std::max(errors.worst_m, (result.T_W_C.translation() - poses[i].translation()).norm());
    errors.worst_deg = std::max(errors.worst_deg, rotationErrorDeg(result.T_W_C, poses[i]));
    errors.last = result.T_W_C;
  }
  return errors;
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

TEST(Tracker, PureTranslationSideways) {
  // 1.6 cm per frame (47 cm/s at 30 Hz), mostly parallel to the plaster wall ahead, over the
  // periodic floor tiles: the hardest direction for frame-to-frame odometry here. It drifts
  // about 7% of the distance (1.4 cm over 17 cm); the test holds it under 10%.
  const synthetic::Scene scene =
      synthetic::loadScene(test::sourceDir() / "config/scenes/office.yaml");
  const Eigen::Vector3d step(0.015, 0.0, 0.005);
  const int frames = 12;
  std::vector<core::Isometry> poses;
  for (int i = 0; i < frames; ++i) poses.push_back(moved(scene.cameraPose(0), step * i, 0.0));
  const PathErrors errors = trackPath(scene, poses);
  EXPECT_LT(errors.worst_m, 0.1 * step.norm() * (frames - 1));
  EXPECT_LT(errors.worst_deg, 0.5);
}

TEST(Tracker, PureRotationOnTheSpot) {
  // 2 degrees per frame (60 deg/s at 30 Hz) with no translation: the case where a
  // translation-biased tracker drifts sideways.
  const synthetic::Scene scene =
      synthetic::loadScene(test::sourceDir() / "config/scenes/office.yaml");
  std::vector<core::Isometry> poses;
  for (int i = 0; i < 12; ++i) poses.push_back(moved(scene.cameraPose(0), {0, 0, 0}, 2.0 * i));
  const PathErrors errors = trackPath(scene, poses);
  EXPECT_LT(errors.worst_m, 0.01);
  EXPECT_LT(errors.worst_deg, 1.0);
}

TEST(Tracker, ALoopReturnsCloseToItsStart) {
  // A 30 cm circle in the horizontal plane, looking about +-10 degrees, back to the start.
  const synthetic::Scene scene =
      synthetic::loadScene(test::sourceDir() / "config/scenes/office.yaml");
  const int steps = 24;
  std::vector<core::Isometry> poses;
  for (int i = 0; i <= steps; ++i) {
    const double a = 2.0 * M_PI * i / steps;
    poses.push_back(moved(scene.cameraPose(0),
                          {0.15 * (1.0 - std::cos(a)), 0.0, 0.15 * std::sin(a)},
                          10.0 * std::sin(a)));
  }
  const PathErrors errors = trackPath(scene, poses);
  EXPECT_LT(errors.worst_m, 0.02);
  EXPECT_LT(errors.worst_deg, 1.0);
  // The loop's end is its start: what is left is the drift accumulated over the loop.
  EXPECT_LT((errors.last.translation() - poses.front().translation()).norm(), 0.02);
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
  // The next frame in sequence is found again against the recent keyframes.
  const core::Frame next = officeFrame(scene, 3);
  const TrackingResult again = tracker.track(next, core::Isometry::Identity());
  EXPECT_EQ(again.status, TrackingStatus::kRelocalised);
  EXPECT_LT(translationError(again.T_W_C, *next.T_W_C_gt), 0.01);
}

TEST(Tracker, FoundAgainstAKeyframeFromBeforeARestartStartsASegmentThere) {
  // Frames 0 to 2, then a view metres away until tracking restarts there at a guessed pose;
  // then the walk again, which a keyframe from before the restart recognises. The pose is in
  // that keyframe's segment, not in the restarted one: the frame starts a segment that names
  // the keyframe, for loop closure to join the two.
  const synthetic::Scene scene =
      synthetic::loadScene(test::sourceDir() / "config/scenes/office.yaml");
  Tracker tracker(TrackerConfig{});
  std::int64_t clock_ns = 0;
  const auto next = [&](int i) {
    core::Frame frame = officeFrame(scene, i);
    frame.timestamp_ns = clock_ns += 33'000'000;
    return frame;
  };
  for (int i = 0; i < 3; ++i) {
    const core::Frame frame = next(i);
    ASSERT_NE(tracker.track(frame, *frame.T_W_C_gt).status, TrackingStatus::kLost);
  }
  TrackingResult away;
  for (int n = 0; n <= TrackerConfig{}.lost_frames_before_restart; ++n) {
    away = tracker.track(next(120), core::Isometry::Identity());
    if (away.status == TrackingStatus::kRestarted) break;
  }
  ASSERT_EQ(away.status, TrackingStatus::kRestarted);
  ASSERT_EQ(away.new_keyframes.size(), 1u);
  const std::int64_t restart_ns = away.new_keyframes.front()->timestamp_ns;
  TrackingResult back;
  core::Frame frame;
  for (int i = 3; i < 8 && back.status != TrackingStatus::kRelocalised; ++i) {
    frame = next(i);
    back = tracker.track(frame, core::Isometry::Identity());
  }
  ASSERT_EQ(back.status, TrackingStatus::kRelocalised) << back.problem;
  EXPECT_LT(translationError(back.T_W_C, *frame.T_W_C_gt), 0.01);
  ASSERT_EQ(back.new_keyframes.size(), 1u);
  EXPECT_TRUE(back.new_keyframes.front()->starts_segment);
  ASSERT_TRUE(back.new_keyframes.front()->relocalised_against_ns.has_value());
  EXPECT_LT(*back.new_keyframes.front()->relocalised_against_ns, restart_ns);
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

// Frame i of the office path with its 30 frames/s timestamp, so that the tracker sees gaps.
core::Frame timedOfficeFrame(const synthetic::Scene& scene, int i) {
  core::Frame frame = officeFrame(scene, i);
  frame.timestamp_ns = static_cast<std::int64_t>(i) * 33'333'333;
  return frame;
}

TEST(Tracker, RecoversAcrossATenFrameGap) {
  // Frames 10 to 19 never arrive (dropped by a busy host): the camera moves about 13 cm and
  // 9 degrees meanwhile. The frame after the gap is posed from features, then refined densely.
  const synthetic::Scene scene =
      synthetic::loadScene(test::sourceDir() / "config/scenes/office.yaml");
  Tracker tracker(TrackerConfig{});
  for (int i = 0; i < 10; ++i) {
    const core::Frame frame = timedOfficeFrame(scene, i);
    ASSERT_NE(tracker.track(frame, *frame.T_W_C_gt).status, TrackingStatus::kLost);
  }
  for (int i = 20; i < 25; ++i) {
    const core::Frame frame = timedOfficeFrame(scene, i);
    const TrackingResult result = tracker.track(frame, core::Isometry::Identity());
    ASSERT_EQ(result.status, TrackingStatus::kTracked) << "frame " << i << ": " << result.problem;
    if (i == 20) {
      EXPECT_TRUE(result.from_features);
    }
    EXPECT_LT(translationError(result.T_W_C, *frame.T_W_C_gt), 0.01) << "frame " << i;
    EXPECT_LT(rotationErrorDeg(result.T_W_C, *frame.T_W_C_gt), 0.5) << "frame " << i;
  }
}

// The planes `frame` shows, in world coordinates at the tracked pose T_W_C.
struct WorldPlane {
  Eigen::Vector3d normal, centroid;
};
std::vector<WorldPlane> worldPlanes(const core::Frame& frame, const core::Isometry& T_W_C) {
  std::vector<WorldPlane> out;
  for (const auto& plane : planes::PlaneDetector(planes::PlaneDetectorConfig{}).detect(frame).planes) {
    out.push_back({T_W_C.linear() * plane.normal_C, T_W_C * plane.centroid_C});
  }
  return out;
}

TEST(Tracker, RelocalisesAfterAReconnectWithTheCameraMoved) {
  // The device is away while the camera moves 30 cm and turns 20 degrees. Tracking on from the
  // last pose would put the frame, and the planes it sees, 30 cm off; relocalised against the
  // keyframes before the gap, it lands where the map is, and the planes seen after the gap line
  // up with those seen before it.
  const synthetic::Scene scene =
      synthetic::loadScene(test::sourceDir() / "config/scenes/office.yaml");
  Tracker tracker(TrackerConfig{});
  const core::Isometry start = scene.cameraPose(0);
  core::Frame before;
  core::Isometry T_W_before = start;
  for (int i = 0; i < 5; ++i) {
    before = officeFrameAt(scene, moved(start, {0.01 * i, 0.0, 0.0}, 0.0), i);
    before.timestamp_ns = static_cast<std::int64_t>(i) * 33'333'333;
    const TrackingResult result = tracker.track(before, start);
    ASSERT_NE(result.status, TrackingStatus::kLost);
    T_W_before = result.T_W_C;
  }
  tracker.sourceInterrupted();
  const core::Isometry away = moved(start, {0.34, 0.0, 0.0}, 20.0);
  core::Frame frame = officeFrameAt(scene, away, 100);
  frame.timestamp_ns = 5'000'000'000;
  const TrackingResult result = tracker.track(frame, core::Isometry::Identity());
  ASSERT_EQ(result.status, TrackingStatus::kRelocalised) << result.problem;
  EXPECT_LT(translationError(result.T_W_C, away), 0.015);
  EXPECT_LT(rotationErrorDeg(result.T_W_C, away), 0.3);

  // Each plane seen after the gap that continues one seen before it (normals within 5
  // degrees, centroids within 10 cm of its plane) lies within 2 cm of it. Without
  // relocalisation the frame would be placed at the last pose, 30 cm and 20 degrees off.
  const auto planes_before = worldPlanes(before, T_W_before);
  const auto planes_after = worldPlanes(frame, result.T_W_C);
  int matched = 0;
  for (const WorldPlane& after : planes_after) {
    for (const WorldPlane& seen : planes_before) {
      const double offset = std::abs(seen.normal.dot(after.centroid - seen.centroid));
      if (seen.normal.dot(after.normal) < std::cos(5.0 * M_PI / 180.0) || offset > 0.10) continue;
      ++matched;
      EXPECT_LT(offset, 0.02) << "plane at " << after.centroid.transpose();
    }
  }
  EXPECT_GE(matched, 2) << planes_before.size() << " planes before, " << planes_after.size()
                        << " after";

  // Tracking goes on from there.
  core::Frame next = officeFrameAt(scene, moved(start, {0.35, 0.0, 0.0}, 20.0), 101);
  next.timestamp_ns = 5'033'333'333;
  const TrackingResult after = tracker.track(next, core::Isometry::Identity());
  EXPECT_EQ(after.status, TrackingStatus::kTracked) << after.problem;
  EXPECT_LT(translationError(after.T_W_C, *next.T_W_C_gt), 0.015);
}

TEST(Tracker, ALostFrameIsRelocalisedAgainstAKeyframeFromTheStartOfTheRun) {
  // Every 3rd frame of the office walk's first 150 (about 2 m), then the camera is back near
  // the start, 5 cm and 5 degrees from frame 0, where none of the last 10 keyframes sees it.
  const synthetic::Scene scene =
      synthetic::loadScene(test::sourceDir() / "config/scenes/office.yaml");
  const auto walkThenReturn = [&](const TrackerConfig& config) {
    Tracker tracker(config);
    for (int i = 0; i < 150; i += 3) {
      const core::Frame frame = timedOfficeFrame(scene, i);
      EXPECT_NE(tracker.track(frame, *frame.T_W_C_gt).status, TrackingStatus::kLost) << i;
    }
    tracker.sourceInterrupted();
    core::Frame back = officeFrameAt(scene, moved(scene.cameraPose(0), {0.05, 0.0, 0.0}, 5.0), 500);
    back.timestamp_ns = 10'000'000'000;
    return std::pair{tracker.track(back, core::Isometry::Identity()), *back.T_W_C_gt};
  };
  const auto [found, truth] = walkThenReturn(TrackerConfig{});
  ASSERT_EQ(found.status, TrackingStatus::kRelocalised) << found.problem;
  EXPECT_TRUE(found.relocalised_globally);
  EXPECT_LT(translationError(found.T_W_C, truth), 0.02);
  EXPECT_LT(rotationErrorDeg(found.T_W_C, truth), 1.0);
  ASSERT_EQ(found.new_keyframes.size(), 1u);
  EXPECT_TRUE(found.new_keyframes.front()->starts_segment);
  // It names the keyframe it was found against, one of the walk's (before 5 s).
  ASSERT_TRUE(found.new_keyframes.front()->relocalised_against_ns.has_value());
  EXPECT_LT(*found.new_keyframes.front()->relocalised_against_ns, 5'000'000'000);

  // Only the recent keyframes: not found again.
  TrackerConfig recent_only;
  recent_only.relocalise_against_all_keyframes = false;
  EXPECT_NE(walkThenReturn(recent_only).first.status, TrackingStatus::kRelocalised);
}

// When loop closure decides which keyframes revisit a kept place, the tracker keeps every
// keyframe to relocalise against until loop closure names it; one named is no longer found.
TEST(Tracker, AKeyframeLoopClosureCoversIsNoLongerRelocalisedAgainst) {
  const synthetic::Scene scene =
      synthetic::loadScene(test::sourceDir() / "config/scenes/office.yaml");
  const auto walkThenReturn = [&](bool forget_the_start) {
    Tracker tracker(TrackerConfig{});
    tracker.leaveCoverToLoopClosure();
    std::vector<std::int64_t> made;
    for (int i = 0; i < 150; i += 3) {
      const core::Frame frame = timedOfficeFrame(scene, i);
      const TrackingResult result = tracker.track(frame, *frame.T_W_C_gt);
      EXPECT_NE(result.status, TrackingStatus::kLost) << i;
      for (const auto& keyframe : result.new_keyframes) {
        EXPECT_TRUE(keyframe->relocalisation);
        made.push_back(keyframe->timestamp_ns);
      }
    }
    EXPECT_GT(made.size(), 10u);
    if (forget_the_start) {
      // The first half of the walk's keyframes, given twice and with an unknown time.
      std::vector<std::int64_t> first_half(made.begin(), made.begin() + made.size() / 2);
      first_half.push_back(first_half.front());
      first_half.push_back(1);
      EXPECT_EQ(tracker.forgetKeyframes(first_half), made.size() / 2);
      EXPECT_EQ(tracker.forgetKeyframes(first_half), 0u);
    }
    tracker.sourceInterrupted();
    core::Frame back = officeFrameAt(scene, moved(scene.cameraPose(0), {0.05, 0.0, 0.0}, 5.0), 500);
    back.timestamp_ns = 10'000'000'000;
    return tracker.track(back, core::Isometry::Identity());
  };
  const TrackingResult kept = walkThenReturn(false);
  EXPECT_EQ(kept.status, TrackingStatus::kRelocalised) << kept.problem;
  EXPECT_TRUE(kept.relocalised_globally);
  EXPECT_FALSE(walkThenReturn(true).relocalised_globally);
}

TEST(Tracker, TracksTheRealDiningRoomKeyframesWithinTenCentimetres) {
  // Five real Kinect frames 23 to 73 cm and 4 to 25 degrees apart: beyond dense odometry, so
  // each step is posed from features and refined. Frame-to-frame odometry ended 765 mm off.
  TESSERA_REQUIRE_SHARED("rgbd/kinect_diningroom_5");
  drivers::DatasetOptions options;
  options.intrinsics = core::parseIntrinsicsSpec("518.0,519.0,325.5,253.5");
  drivers::DatasetSource source(test::sharedData() / "rgbd/kinect_diningroom_5", options);
  Tracker tracker(TrackerConfig{});
  core::Trajectory estimate, truth;
  std::optional<core::Isometry> first;
  for (core::ReadResult read = source.read(); read.status != core::ReadStatus::kEndOfData;
       read = source.read()) {
    ASSERT_EQ(read.status, core::ReadStatus::kFrame);
    const core::Frame frame = core::withRegisteredColour(std::move(read.frame));
    if (!first) first = *frame.T_W_C_gt;
    const TrackingResult result = tracker.track(frame, *first);
    ASSERT_NE(result.status, TrackingStatus::kLost)
        << "frame " << frame.index << ": " << result.problem;
    estimate[frame.timestamp_ns] = result.T_W_C;
    truth[frame.timestamp_ns] = *frame.T_W_C_gt;
  }
  const auto ate = core::absoluteTrajectoryError(estimate, truth);
  ASSERT_TRUE(ate.has_value());
  EXPECT_EQ(ate->pairs, 5u);
  EXPECT_LT(ate->rmse_m, 0.10);  // 31 mm measured
}

}  // namespace
}  // namespace tessera::fusion
