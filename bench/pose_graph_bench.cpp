// The pose graph's solve time against its size: a ring of --nodes-per-lap nodes walked more
// and more laps (a robot going round the same building) with drifting odometry, a true loop
// from every other node of the later laps to the first lap and --wrong-loops wrong ones, solved
// by tessera's sparse solver and, up to --dense-max-nodes, by Open3D's dense one (the solver it
// replaced). Prints per graph: nodes, edges, loops, milliseconds of each, their largest
// disagreement, the error against the truth, and whether every loop was judged right by each.
//
//   pose_graph_bench [--laps 2,3,6,...] [--nodes-per-lap N] [--yaw-bias-deg D]
//                    [--wrong-loops N] [--dense-max-nodes N]
#include <chrono>
#include <vector>

#include <fmt/format.h>
#include <CLI/CLI.hpp>

#include "../tests/support/open3d_pose_graph.h"
#include "../tests/support/pose_graph_ring.h"
#include "tessera/loop/pose_graph.h"

namespace {

using tessera::core::Isometry;

double worstDistance(const std::vector<Isometry>& a, const std::vector<Isometry>& b) {
  double worst = 0.0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    worst = std::max(worst, (a[i].translation() - b[i].translation()).norm());
  }
  return worst;
}

template <typename Solve>
double timedMs(Solve&& solve) {
  const auto start = std::chrono::steady_clock::now();
  solve();
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
      .count();
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Pose-graph solve time: tessera's sparse solver against Open3D's dense one"};
  int per_lap = 100;
  double yaw_bias_deg = 0.01;
  std::size_t dense_max_nodes = 600;
  int wrong_loops = 3;
  std::vector<int> laps_list{2, 3, 6, 12, 24};
  app.add_option("--nodes-per-lap", per_lap, "Nodes per lap of the ring")
      ->check(CLI::Range(8, 10000));
  app.add_option("--yaw-bias-deg", yaw_bias_deg, "Odometry's yaw error per step, degrees");
  app.add_option("--dense-max-nodes", dense_max_nodes,
                 "Largest graph given to Open3D's dense solver (its memory is quadratic)");
  app.add_option("--wrong-loops", wrong_loops, "Wrong loops per graph (opposite sides as one)");
  app.add_option("--laps", laps_list, "Laps of the ring, one graph each")->delimiter(',');
  CLI11_PARSE(app, argc, argv);

  fmt::print("{:>6} {:>6} {:>6} {:>10} {:>10} {:>10} {:>9} {:>7} {:>7}\n", "nodes", "edges",
             "loops", "sparse_ms", "dense_ms", "differ_mm", "error_mm", "judged", "dense");
  for (const int laps : laps_list) {
    const auto ring = tessera::test::walkRing(per_lap, laps, 2, wrong_loops, yaw_bias_deg, 42);
    const double distance = 0.3 + 0.05 * ring.path_m;
    tessera::loop::GraphSolution sparse, dense;
    const double sparse_ms = timedMs([&] {
      sparse = tessera::loop::optimisePoseGraph(ring.tracked, ring.edges, 0.25, distance);
    });
    std::string dense_ms = "-", differ_mm = "-", dense_judged = "-";
    if (ring.tracked.size() <= dense_max_nodes) {
      dense_ms = fmt::format("{:.0f}", timedMs([&] {
                               dense = tessera::test::optimiseWithOpen3D(ring.tracked, ring.edges,
                                                                         0.25, distance);
                             }));
      differ_mm = fmt::format("{:.2f}", 1e3 * worstDistance(sparse.T_W_C, dense.T_W_C));
      dense_judged = dense.loop_kept == ring.loop_is_true ? "all" : "WRONG";
    }
    fmt::print("{:>6} {:>6} {:>6} {:>10.1f} {:>10} {:>10} {:>9.1f} {:>7} {:>7}\n",
               ring.tracked.size(), ring.edges.size(), ring.loop_is_true.size(), sparse_ms,
               dense_ms, differ_mm, 1e3 * worstDistance(sparse.T_W_C, ring.truth),
               sparse.loop_kept == ring.loop_is_true ? "all" : "WRONG", dense_judged);
  }
  return 0;
}
