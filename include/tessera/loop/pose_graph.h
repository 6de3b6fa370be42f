#pragma once
// The pose graph of the keyframes: Levenberg-Marquardt with a line process on the loop edges
// (Choi et al. 2015), which prunes loops that disagree with the rest of the graph. Its normal
// equations are sparse (each node meets its odometry neighbours and a few loops), factorised by
// Eigen's sparse LDLT: a solve costs about linear time and memory in the nodes. Open3D's
// GlobalOptimization, which the same method came from, builds them densely (6N x 6N, cubic
// time and quadratic memory); its conventions are kept, so Open3D's information matrices apply.
//
// The line process weighs each loop by its residual at the start, against a distance: a true
// loop that closes more drift than that distance starts with almost no weight and is pruned.
// So the graph is solved twice: first with the distance the loops' drift bound allows (the
// loops that agree pull the graph together; one far off still loses its weight), then from that
// solution with the usual 7.5 cm, where a loop that disagrees with the others is pruned.
//
// Thread-safety: a pure function of its arguments.
#include <vector>

#include "tessera/core/pose.h"
#include "tessera/loop/revisit.h"

namespace tessera::loop {

struct GraphEdge {
  int source = 0;  // node indices
  int target = 0;
  core::Isometry T_target_source = core::Isometry::Identity();
  Matrix6d information = Matrix6d::Identity();
  bool loop = false;  // a revisit (may be pruned) rather than odometry (kept)
};

struct GraphSolution {
  std::vector<core::Isometry> T_W_C;  // per node, the first node kept where it was
  std::vector<bool> loop_kept;        // per loop edge, in the order given
  double ms = 0.0;
};

// Optimises the node poses `T_W_C` (their initial values) under `edges`. Loop edges whose
// line-process weight ends below `edge_prune_threshold` are pruned and reported as not kept.
// `drift_distance_m` is the first solve's line-process distance (see above).
GraphSolution optimisePoseGraph(const std::vector<core::Isometry>& T_W_C,
                                const std::vector<GraphEdge>& edges, double edge_prune_threshold,
                                double drift_distance_m);

}  // namespace tessera::loop
