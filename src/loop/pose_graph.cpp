#include "tessera/loop/pose_graph.h"

#include <algorithm>
#include <chrono>
#include <set>
#include <utility>

#include <open3d/pipelines/registration/GlobalOptimization.h>
#include <open3d/pipelines/registration/PoseGraph.h>
#include <open3d/utility/Logging.h>

namespace tessera::loop {

namespace reg = open3d::pipelines::registration;

// The distance Open3D's line process scales loop residuals by (its documented default).
constexpr double kLineProcessDistanceM = 0.075;

namespace {

void solve(reg::PoseGraph& graph, double line_process_distance_m, double edge_prune_threshold) {
  // Open3D reports each iteration at Info level; tessera's log says what matters.
  const auto verbosity = open3d::utility::GetVerbosityLevel();
  open3d::utility::SetVerbosityLevel(open3d::utility::VerbosityLevel::Error);
  reg::GlobalOptimization(graph, reg::GlobalOptimizationLevenbergMarquardt(),
                          reg::GlobalOptimizationConvergenceCriteria(),
                          reg::GlobalOptimizationOption(line_process_distance_m,
                                                        edge_prune_threshold, 1.0, 0));
  open3d::utility::SetVerbosityLevel(verbosity);
}

}  // namespace

GraphSolution optimisePoseGraph(const std::vector<core::Isometry>& T_W_C,
                                const std::vector<GraphEdge>& edges, double edge_prune_threshold,
                                double drift_distance_m) {
  const auto start = std::chrono::steady_clock::now();
  GraphSolution out;
  reg::PoseGraph graph;
  for (const core::Isometry& pose : T_W_C) graph.nodes_.emplace_back(pose.matrix());
  for (const GraphEdge& edge : edges) {
    // Open3D: an edge's transformation takes source points to the target's frame, and a loop
    // is "uncertain" (weighed by the line process).
    graph.edges_.emplace_back(edge.source, edge.target, edge.T_target_source.matrix(),
                              edge.information, edge.loop, 1.0);
  }
  if (T_W_C.size() >= 2) {
    // First solve: the drift-sized distance; its poses start the second, on every edge again.
    reg::PoseGraph coarse = graph;
    solve(coarse, std::max(drift_distance_m, kLineProcessDistanceM), edge_prune_threshold);
    for (std::size_t i = 0; i < graph.nodes_.size(); ++i) graph.nodes_[i] = coarse.nodes_[i];
    solve(graph, kLineProcessDistanceM, edge_prune_threshold);
  }
  for (const auto& node : graph.nodes_) {
    core::Isometry pose;
    pose.matrix() = node.pose_;
    out.T_W_C.push_back(pose);
  }
  std::set<std::pair<int, int>> kept;
  for (const auto& edge : graph.edges_) {
    if (edge.uncertain_) kept.emplace(edge.source_node_id_, edge.target_node_id_);
  }
  for (const GraphEdge& edge : edges) {
    if (edge.loop) out.loop_kept.push_back(kept.count({edge.source, edge.target}) > 0);
  }
  out.ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
               .count();
  return out;
}

}  // namespace tessera::loop
