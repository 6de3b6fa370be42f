// The two small solves of view selection: which view each region takes, and each view's gain.
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

#include <Eigen/SparseCholesky>
#include <Eigen/SparseCore>

#include "tessera/texture/view_selection.h"

namespace tessera::texture {

namespace {

constexpr double kMaxDataCost = 4.0;  // a view e^4 = 55 times lighter than the best is as bad
constexpr int kIterations = 12;
constexpr std::array<int, 4> kStepX = {1, -1, 0, 0}, kStepY = {0, 0, 1, -1};
constexpr std::array<int, 4> kOpposite = {1, 0, 3, 2};

double dataCost(const RegionViews& region, std::size_t label) {
  return std::min(std::log(region.weights.front() / std::max(region.weights[label], 1e-300)),
                  kMaxDataCost);
}

}  // namespace

std::vector<int> labelRegions(const std::vector<RegionViews>& regions, int columns, int rows,
                              double smoothness) {
  const auto count = static_cast<std::size_t>(columns) * static_cast<std::size_t>(rows);
  // incoming[i][d][l]: the message region i gets from its neighbour in direction d, over i's
  // candidates l.
  std::vector<std::array<std::vector<double>, 4>> incoming(count);
  for (std::size_t i = 0; i < count; ++i) {
    for (auto& message : incoming[i]) message.assign(regions[i].views.size(), 0.0);
  }
  const auto neighbour = [&](std::size_t i, int d) -> long {
    const int x = static_cast<int>(i % static_cast<std::size_t>(columns)) + kStepX[d];
    const int y = static_cast<int>(i / static_cast<std::size_t>(columns)) + kStepY[d];
    if (x < 0 || y < 0 || x >= columns || y >= rows) return -1;
    const long j = static_cast<long>(y) * columns + x;
    return regions[static_cast<std::size_t>(j)].views.empty() ? -1 : j;
  };
  std::vector<double> belief, message;
  for (int iteration = 0; iteration < kIterations; ++iteration) {
    for (std::size_t i = 0; i < count; ++i) {
      const RegionViews& from = regions[i];
      if (from.views.empty()) continue;
      belief.assign(from.views.size(), 0.0);
      for (std::size_t l = 0; l < from.views.size(); ++l) {
        belief[l] = dataCost(from, l);
        for (const auto& in : incoming[i]) belief[l] += in[l];
      }
      for (int d = 0; d < 4; ++d) {
        const long j = neighbour(i, d);
        if (j < 0) continue;
        const RegionViews& to = regions[static_cast<std::size_t>(j)];
        const std::vector<double>& back = incoming[i][d];  // what j told i: left out
        message.assign(to.views.size(), std::numeric_limits<double>::infinity());
        for (std::size_t k = 0; k < to.views.size(); ++k) {
          for (std::size_t l = 0; l < from.views.size(); ++l) {
            const double seam = from.views[l] == to.views[k] ? 0.0 : smoothness;
            message[k] = std::min(message[k], belief[l] - back[l] + seam);
          }
        }
        const double lowest = *std::min_element(message.begin(), message.end());
        for (double& m : message) m -= lowest;  // keeps the messages bounded
        incoming[static_cast<std::size_t>(j)][kOpposite[d]] = message;
      }
    }
  }
  std::vector<int> labels(count, -1);
  for (std::size_t i = 0; i < count; ++i) {
    const RegionViews& region = regions[i];
    double best = std::numeric_limits<double>::infinity();
    for (std::size_t l = 0; l < region.views.size(); ++l) {
      double cost = dataCost(region, l);
      for (const auto& in : incoming[i]) cost += in[l];
      if (cost < best - 1e-12) best = cost, labels[i] = static_cast<int>(l);
    }
  }
  // Where two labellings tie, belief propagation can decode each region to a different one
  // (two views equally good over a strip come out alternating); a few sweeps of iterated
  // conditional modes, each region taking its best view given its neighbours' views, settle it.
  for (int sweep = 0; sweep < 3; ++sweep) {
    for (std::size_t i = 0; i < count; ++i) {
      const RegionViews& region = regions[i];
      double best = std::numeric_limits<double>::infinity();
      for (std::size_t l = 0; l < region.views.size(); ++l) {
        double cost = dataCost(region, l);
        for (int d = 0; d < 4; ++d) {
          const long j = neighbour(i, d);
          if (j < 0) continue;
          const auto& other = regions[static_cast<std::size_t>(j)];
          const int k = labels[static_cast<std::size_t>(j)];
          if (other.views[static_cast<std::size_t>(k)] != region.views[l]) cost += smoothness;
        }
        if (cost < best - 1e-12) best = cost, labels[i] = static_cast<int>(l);
      }
    }
  }
  return labels;
}

std::vector<cv::Vec3d> viewLogGains(int views, const std::vector<ViewPair>& pairs) {
  std::vector<cv::Vec3d> gains(static_cast<std::size_t>(views), cv::Vec3d(0, 0, 0));
  if (pairs.empty()) return gains;
  // The normal equations of the least squares: a weighted graph Laplacian plus the prior
  // mu n_v on the diagonal, which pulls the gains towards none (and makes it positive definite).
  constexpr double kPrior = 0.05;
  std::vector<double> shared(static_cast<std::size_t>(views), 0.0);
  std::vector<Eigen::Triplet<double>> entries;
  Eigen::MatrixXd rhs = Eigen::MatrixXd::Zero(views, 3);
  for (const ViewPair& pair : pairs) {
    entries.emplace_back(pair.a, pair.a, pair.shared);
    entries.emplace_back(pair.b, pair.b, pair.shared);
    entries.emplace_back(pair.a, pair.b, -pair.shared);
    entries.emplace_back(pair.b, pair.a, -pair.shared);
    shared[static_cast<std::size_t>(pair.a)] += pair.shared;
    shared[static_cast<std::size_t>(pair.b)] += pair.shared;
    for (int c = 0; c < 3; ++c) {
      rhs(pair.a, c) += pair.shared * pair.log_ratio[c];
      rhs(pair.b, c) -= pair.shared * pair.log_ratio[c];
    }
  }
  for (int v = 0; v < views; ++v) {
    entries.emplace_back(v, v, kPrior * shared[static_cast<std::size_t>(v)] + 1e-9);
  }
  Eigen::SparseMatrix<double> normal(views, views);
  normal.setFromTriplets(entries.begin(), entries.end());
  const Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> solver(normal);
  if (solver.info() != Eigen::Success) return gains;
  const Eigen::MatrixXd solution = solver.solve(rhs);
  for (int v = 0; v < views; ++v) {
    for (int c = 0; c < 3; ++c) gains[static_cast<std::size_t>(v)][c] = solution(v, c);
  }
  return gains;
}

}  // namespace tessera::texture
