// The pose graph's sparse solver: against Open3D's dense solve, the plain reference it
// replaces, and against the truth on rings walked several laps with drifting odometry, true
// loops and wrong ones.
#include <algorithm>
#include <vector>

#include <gtest/gtest.h>

#include "support/open3d_pose_graph.h"
#include "support/pose_graph_ring.h"
#include "tessera/loop/pose_graph.h"

namespace tessera::loop {
namespace {

constexpr double kPruneThreshold = 0.25;

// The first solve's distance: what a 0.3 m + 5 % drift bound allows over the ring's path.
double driftDistance(const test::PoseGraphRing& ring) { return 0.3 + 0.05 * ring.path_m; }

double worstPositionError(const std::vector<core::Isometry>& a,
                          const std::vector<core::Isometry>& b) {
  double worst = 0.0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    worst = std::max(worst, (a[i].translation() - b[i].translation()).norm());
  }
  return worst;
}

double worstRotationErrorDeg(const std::vector<core::Isometry>& a,
                             const std::vector<core::Isometry>& b) {
  double worst = 0.0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    worst = std::max(worst, core::rotationAngleDeg(a[i].inverse() * b[i]));
  }
  return worst;
}

void expectTrueLoopsKeptAndWrongOnesPruned(const test::PoseGraphRing& ring,
                                           const GraphSolution& solution) {
  ASSERT_EQ(solution.loop_kept.size(), ring.loop_is_true.size());
  for (std::size_t i = 0; i < ring.loop_is_true.size(); ++i) {
    EXPECT_EQ(solution.loop_kept[i], ring.loop_is_true[i])
        << "loop " << i
        << (ring.loop_is_true[i] ? " is true and was pruned" : " is wrong and was kept");
  }
}

TEST(PoseGraph, AgreesWithOpen3DsDenseSolveOverThreeLaps) {
  const test::PoseGraphRing ring = test::walkRing(36, 3, 2, 3, 0.15, 7);
  const double drift = worstPositionError(ring.tracked, ring.truth);
  ASSERT_GT(drift, 0.5);
  const GraphSolution sparse =
      optimisePoseGraph(ring.tracked, ring.edges, kPruneThreshold, driftDistance(ring));
  const GraphSolution dense =
      test::optimiseWithOpen3D(ring.tracked, ring.edges, kPruneThreshold, driftDistance(ring));
  expectTrueLoopsKeptAndWrongOnesPruned(ring, sparse);
  EXPECT_EQ(sparse.loop_kept, dense.loop_kept);
  EXPECT_LT(worstPositionError(sparse.T_W_C, dense.T_W_C), 0.005);
  EXPECT_LT(worstRotationErrorDeg(sparse.T_W_C, dense.T_W_C), 0.2);
  EXPECT_LT(worstPositionError(sparse.T_W_C, ring.truth), 0.05 * drift)
      << "drift before: " << drift << " m";
}

// 1,200 nodes: Open3D's dense normal equations alone would take 7,200 x 7,200 doubles (415 MB).
TEST(PoseGraph, SolvesAThousandNodeGraphToTheTruth) {
  const test::PoseGraphRing ring = test::walkRing(300, 4, 5, 10, 0.02, 11);
  const double drift = worstPositionError(ring.tracked, ring.truth);
  ASSERT_GT(drift, 0.5);
  const GraphSolution solution =
      optimisePoseGraph(ring.tracked, ring.edges, kPruneThreshold, driftDistance(ring));
  expectTrueLoopsKeptAndWrongOnesPruned(ring, solution);
  EXPECT_LT(worstPositionError(solution.T_W_C, ring.truth), 0.05 * drift)
      << "drift before: " << drift << " m";
  EXPECT_LT(worstRotationErrorDeg(solution.T_W_C, ring.truth), 1.0);
}

}  // namespace
}  // namespace tessera::loop
