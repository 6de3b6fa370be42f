// The integration stage with loop closure: a frame is fused at its keyframe's corrected pose,
// so that a place seen again lands on what was fused there instead of beside it.
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

}  // namespace
}  // namespace tessera::pipeline
