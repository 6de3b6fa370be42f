// The integration stage with loop closure: a frame is fused at its keyframe's corrected pose,
// so that a place seen again lands on what was fused there instead of beside it, and the
// frames of a segment tracking restarted are held apart until loop closure joins it.
#include <memory>

#include <gtest/gtest.h>

#include "support/synthetic_plane.h"
#include "tessera/pipeline/stages.h"

namespace tessera::pipeline {
namespace {

// A plane 1.4 m in front of a camera at the origin, tracked there, its keyframe at time 0.
TrackedFrame planeFrame() {
  const Eigen::Vector3d n = Eigen::Vector3d(0.1, 0.2, -1.0).normalized();
  TrackedFrame tracked;
  tracked.frame =
      test::renderPlane(test::kinectIntrinsics(), core::Isometry::Identity(), n, n.z() * 1.4);
  tracked.frame.timestamp_ns = 1'000'000'000;
  tracked.T_W_C = core::Isometry::Identity();
  tracked.keyframe_ns = 0;
  return tracked;
}

Eigen::Vector3d meanVertex(const fusion::SurfaceMesh& mesh) {
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  for (const Eigen::Vector3d& v : mesh.vertices) sum += v;
  return sum / static_cast<double>(mesh.vertices.size());
}

TEST(IntegrationStage, FusesAFrameAtItsKeyframesCorrectedPose) {
  const fusion::TsdfConfig tsdf;
  IntegrationStage tracked_only(tsdf, 1);
  ASSERT_TRUE(tracked_only.process(planeFrame()).integrated);
  const fusion::SurfaceMesh at_tracked = tracked_only.takeSurface();
  ASSERT_GT(at_tracked.vertices.size(), 1000u);

  // Loop closure moved the frame's keyframe 0.5 m along x and 10 degrees about z.
  auto correction = std::make_shared<loop::MapCorrection>();
  correction->generation = 1;
  correction->keyframe_ns = {0};
  core::Isometry motion(Eigen::AngleAxisd(10.0 * M_PI / 180.0, Eigen::Vector3d::UnitZ()));
  motion.translation() = Eigen::Vector3d(0.5, 0.0, 0.0);
  correction->motion = {motion};
  IntegrationStage corrected(tsdf, 1);
  corrected.followLoopClosure(correction);
  const FusedFrame fused = corrected.process(planeFrame());
  ASSERT_TRUE(fused.integrated);
  EXPECT_TRUE(fused.T_W_C->isApprox(core::Isometry::Identity())) << "the tracked pose is kept";
  const fusion::SurfaceMesh at_corrected = corrected.takeSurface();
  ASSERT_GT(at_corrected.vertices.size(), 1000u);
  // The same surface, moved: its centre within 2 voxels (2 cm) of the tracked one's, moved.
  EXPECT_LT((meanVertex(at_corrected) - motion * meanVertex(at_tracked)).norm(), 0.02);
}

// planeFrame() at time `t_s`, which made a keyframe then (one that starts a segment or not).
TrackedFrame frameWithKeyframe(std::int64_t t_s, bool starts_segment) {
  TrackedFrame tracked = planeFrame();
  tracked.frame.index = static_cast<std::uint64_t>(t_s);
  tracked.frame.timestamp_ns = t_s * 1'000'000'000;
  tracked.keyframe_ns = tracked.frame.timestamp_ns;
  auto keyframe = std::make_shared<fusion::KeyframeRecord>();
  keyframe->timestamp_ns = tracked.frame.timestamp_ns;
  keyframe->starts_segment = starts_segment;
  tracked.new_keyframes.push_back(keyframe);
  return tracked;
}

// A correction that knows keyframes at 1 s and 3 s, the second's segment joined or not.
std::shared_ptr<loop::MapCorrection> correctionOf(bool joined) {
  auto correction = std::make_shared<loop::MapCorrection>();
  correction->generation = joined ? 2 : 1;
  correction->keyframe_ns = {1'000'000'000, 3'000'000'000};
  correction->motion = {core::Isometry::Identity(), core::Isometry::Identity()};
  correction->in_map = {true, joined};
  return correction;
}

TEST(IntegrationStage, HoldsASegmentAfterARestartApartUntilItIsJoined) {
  fusion::TsdfConfig every_frame;
  every_frame.integrate_every_n_frames = 1;
  IntegrationStage stage(every_frame, 1);
  stage.holdApartUnjoinedSegments();
  // The run's first keyframe starts the first segment: fused.
  EXPECT_TRUE(stage.process(frameWithKeyframe(1, true)).integrated);
  // Tracking restarted at 3 s: held apart, the tracker's pose kept, the reason said.
  FusedFrame apart = stage.process(frameWithKeyframe(3, true));
  EXPECT_FALSE(apart.integrated);
  EXPECT_TRUE(apart.held_apart);
  EXPECT_TRUE(apart.T_W_C.has_value());
  EXPECT_FALSE(mapPoseOf(apart).has_value()) << "not a pose in the map's frame";
  EXPECT_NE(apart.skip_reason.find("begun at frame 3"), std::string::npos) << apart.skip_reason;
  // A correction that knows the segment but has not joined it: still apart.
  stage.followLoopClosure(correctionOf(false));
  EXPECT_TRUE(stage.process(frameWithKeyframe(4, false)).held_apart);
  // Joined: fused from here.
  stage.followLoopClosure(correctionOf(true));
  const FusedFrame joined = stage.process(frameWithKeyframe(5, false));
  EXPECT_TRUE(joined.integrated);
  EXPECT_FALSE(joined.held_apart);
  EXPECT_EQ(stage.figures().frames_held_apart, 2u);
  // Another restart, newer than every keyframe the correction knows: apart again.
  EXPECT_TRUE(stage.process(frameWithKeyframe(6, true)).held_apart);

  // Without holding apart, a restarted segment is fused at its guessed pose.
  IntegrationStage fuses_all(every_frame, 1);
  EXPECT_TRUE(fuses_all.process(frameWithKeyframe(1, true)).integrated);
  EXPECT_TRUE(fuses_all.process(frameWithKeyframe(3, true)).integrated);
}

}  // namespace
}  // namespace tessera::pipeline
