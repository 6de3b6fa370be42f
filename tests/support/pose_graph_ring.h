#pragma once
// A pose graph with known truth: a camera walking laps of a 3 m circle (one node every
// 360/nodes_per_lap degrees, bobbing 5 cm up and down), odometry that turns a little too far at
// each step (yaw_bias_deg), true loops from every loop_every-th node of the later laps to the
// first, and wrong loops as a repeated pattern would fake them. Shared by the pose-graph tests and
// bench/pose_graph_bench.
#include <cmath>
#include <cstdint>
#include <random>
#include <vector>

#include "tessera/core/pose.h"
#include "tessera/loop/pose_graph.h"

namespace tessera::test {

struct PoseGraphRing {
  std::vector<core::Isometry> truth;
  std::vector<core::Isometry> tracked;
  std::vector<loop::GraphEdge> edges;  // odometry first, then the loops
  std::vector<bool> loop_is_true;      // per loop edge, in order
  double path_m = 0.0;
};

inline PoseGraphRing walkRing(int nodes_per_lap, int laps, int loop_every, int wrong_loops,
                              double yaw_bias_deg, std::uint32_t seed) {
  std::mt19937 random(seed);
  std::normal_distribution<double> noise(0.0, 1.0);
  PoseGraphRing ring;
  const int n = nodes_per_lap * laps;
  for (int i = 0; i < n; ++i) {
    const double a = 2.0 * M_PI * i / nodes_per_lap;
    core::Isometry T = core::Isometry::Identity();
    T.linear() = Eigen::AngleAxisd(a, Eigen::Vector3d::UnitZ()).toRotationMatrix();
    T.translation() = Eigen::Vector3d(3.0 * std::cos(a), 3.0 * std::sin(a), 0.05 * std::sin(5 * a));
    ring.truth.push_back(T);
  }
  const loop::Matrix6d information = loop::Matrix6d::Identity() * 1e4;
  ring.tracked.push_back(ring.truth[0]);
  for (int i = 1; i < n; ++i) {
    // yaw_bias_deg of yaw too many per step, plus a millimetre and 0.05 degrees of noise.
    const Eigen::Vector3d tilt(noise(random), noise(random), noise(random));
    core::Isometry error(Eigen::AngleAxisd(yaw_bias_deg * M_PI / 180.0, Eigen::Vector3d::UnitZ()) *
                         Eigen::AngleAxisd(0.05 * M_PI / 180.0 * tilt.norm(), tilt.normalized()));
    error.translation() = 1e-3 * Eigen::Vector3d(noise(random), noise(random), noise(random));
    const core::Isometry step = ring.truth[static_cast<std::size_t>(i - 1)].inverse() *
                                ring.truth[static_cast<std::size_t>(i)] * error;
    ring.tracked.push_back(ring.tracked.back() * step);
    ring.path_m += step.translation().norm();
    ring.edges.push_back({i - 1, i, step.inverse(), information, false});
  }
  for (int i = nodes_per_lap; i < n; i += loop_every) {
    const int first_lap = i % nodes_per_lap;
    const auto& source = ring.truth[static_cast<std::size_t>(first_lap)];
    const auto& target = ring.truth[static_cast<std::size_t>(i)];
    ring.edges.push_back({first_lap, i, target.inverse() * source, information, true});
    ring.loop_is_true.push_back(true);
  }
  // A wrong loop as one that passed the loop closer's checks would be: a later lap's node
  // matched to its first-lap place with a pose 0.6 m and 3 degrees off (a repeated pattern
  // faking the view), within the drift bound.
  std::uniform_int_distribution<int> node(nodes_per_lap, n - 1);
  for (int w = 0; w < wrong_loops; ++w) {
    const int query = node(random);
    const int place = query % nodes_per_lap;
    core::Isometry fake(Eigen::AngleAxisd(3.0 * M_PI / 180.0, Eigen::Vector3d::UnitZ()));
    fake.translation() = Eigen::Vector3d(0.6, 0.0, 0.0);
    const auto& source = ring.truth[static_cast<std::size_t>(place)];
    const auto& target = ring.truth[static_cast<std::size_t>(query)];
    ring.edges.push_back({place, query, fake * target.inverse() * source, information, true});
    ring.loop_is_true.push_back(false);
  }
  return ring;
}

}  // namespace tessera::test
