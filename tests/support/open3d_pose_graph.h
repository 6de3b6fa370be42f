#pragma once
// The reference for tessera's sparse pose-graph solver: Open3D's dense GlobalOptimization
// (Levenberg-Marquardt with the line process), called the way tessera's solver is used: a
// first solve at the drift-sized distance, then from its poses at 7.5 cm on every edge again.
// Only for tests and benches: it costs cubic time and quadratic memory in the nodes.
#include <algorithm>
#include <vector>

#include <open3d/pipelines/registration/GlobalOptimization.h>
#include <open3d/pipelines/registration/PoseGraph.h>
#include <open3d/utility/Logging.h>

#include "tessera/loop/pose_graph.h"

namespace tessera::test {

inline loop::GraphSolution optimiseWithOpen3D(const std::vector<core::Isometry>& T_W_C,
                                              const std::vector<loop::GraphEdge>& edges,
                                              double edge_prune_threshold,
                                              double drift_distance_m) {
  namespace reg = open3d::pipelines::registration;
  open3d::utility::SetVerbosityLevel(open3d::utility::VerbosityLevel::Error);
  const auto solve = [&](reg::PoseGraph& graph, double distance_m) {
    reg::GlobalOptimization(
        graph, reg::GlobalOptimizationLevenbergMarquardt(),
        reg::GlobalOptimizationConvergenceCriteria(),
        reg::GlobalOptimizationOption(distance_m, edge_prune_threshold, 1.0, 0));
  };
  reg::PoseGraph graph;
  for (const core::Isometry& pose : T_W_C) graph.nodes_.emplace_back(pose.matrix());
  for (const loop::GraphEdge& edge : edges) {
    graph.edges_.emplace_back(edge.source, edge.target, edge.T_target_source.matrix(),
                              edge.information, edge.loop, 1.0);
  }
  reg::PoseGraph coarse = graph;
  solve(coarse, std::max(drift_distance_m, 0.075));
  for (std::size_t i = 0; i < graph.nodes_.size(); ++i) graph.nodes_[i] = coarse.nodes_[i];
  solve(graph, 0.075);
  loop::GraphSolution out;
  for (const auto& node : graph.nodes_) {
    core::Isometry pose;
    pose.matrix() = node.pose_;
    out.T_W_C.push_back(pose);
  }
  // Open3D keeps the edges' order when it prunes: walk the loops given against those left.
  std::size_t left = 0;
  for (const loop::GraphEdge& edge : edges) {
    while (left < graph.edges_.size() && !graph.edges_[left].uncertain_) ++left;
    if (!edge.loop) continue;
    const bool kept = left < graph.edges_.size() &&
                      graph.edges_[left].source_node_id_ == edge.source &&
                      graph.edges_[left].target_node_id_ == edge.target;
    out.loop_kept.push_back(kept);
    if (kept) ++left;
  }
  return out;
}

}  // namespace tessera::test
