#include "tessera/loop/pose_graph.h"

#include <algorithm>
#include <chrono>
#include <cmath>

#include <Eigen/SparseCholesky>
#include <Eigen/SparseCore>

namespace tessera::loop {

namespace {

using Vector6d = Eigen::Matrix<double, 6, 1>;
using SparseMatrix = Eigen::SparseMatrix<double>;

// The distance the line process scales loop residuals by (Choi et al. 2015, Section 5; Open3D's
// default).
constexpr double kLineProcessDistanceM = 0.075;

// Levenberg-Marquardt's stopping rules (Open3D's defaults, so the solution matches its solver).
constexpr int kMaxIterations = 100;
constexpr int kMaxDampingTries = 20;
constexpr double kMinRelativeStep = 1e-6;
constexpr double kMinRelativeDecrease = 1e-6;
constexpr double kMinGradient = 1e-6;
constexpr double kMinCost = 1e-6;

// The conventions of Choi et al. 2015 (and Open3D's information matrices): a 6-vector is
// [rotation; translation], and a small motion d = [w; v] acts on a pose from the left as
// (I + [w]x, v).

Eigen::Matrix3d skew(const Eigen::Vector3d& w) {
  Eigen::Matrix3d out;
  out << 0.0, -w.z(), w.y(), w.z(), 0.0, -w.x(), -w.y(), w.x(), 0.0;
  return out;
}

// The rotation vector of a near-identity matrix's antisymmetric part, and its translation.
Vector6d linearised(const Eigen::Matrix3d& R, const Eigen::Vector3d& t) {
  Vector6d out;
  out << (R(2, 1) - R(1, 2)) / 2.0, (R(0, 2) - R(2, 0)) / 2.0, (R(1, 0) - R(0, 1)) / 2.0, t;
  return out;
}

struct Edge {
  int source = 0;
  int target = 0;
  Eigen::Isometry3d T_source_target;  // the measurement, inverted
  Matrix6d information;
  bool loop = false;
  double confidence = 1.0;  // the line process l (Choi et al. 2015, Eq. 2); 1 for odometry
  std::size_t given = 0;    // its place among the edges given
};

// One edge's misalignment e = linearised(X^-1 T_t^-1 T_s) (Choi et al. 2015, Eq. 6), and its
// Jacobian in the source's motion; the target's is its negative, as T_t^-1 moves by exp(-d).
struct Linearisation {
  Vector6d residual;
  Matrix6d J_source;
};

Linearisation linearise(const Edge& edge, const std::vector<Eigen::Isometry3d>& poses) {
  const Eigen::Isometry3d A =
      edge.T_source_target * poses[static_cast<std::size_t>(edge.target)].inverse();
  const Eigen::Isometry3d& T_s = poses[static_cast<std::size_t>(edge.source)];
  const Eigen::Isometry3d M = A * T_s;
  Linearisation out;
  out.residual = linearised(M.linear(), M.translation());
  // A (I + G(d)) T_s - A T_s = A G(d) T_s, linear in d: rotation A_R [w]x T_R, translation
  // A_R ([w]x T_p + v).
  const Eigen::Matrix3d& A_R = A.linear();
  out.J_source.setZero();
  for (int i = 0; i < 3; ++i) {
    const Eigen::Matrix3d K = A_R * skew(Eigen::Vector3d::Unit(i)) * T_s.linear();
    out.J_source.block<3, 1>(0, i) = linearised(K, Eigen::Vector3d::Zero()).head<3>();
  }
  out.J_source.block<3, 3>(3, 0) = -A_R * skew(T_s.translation());
  out.J_source.block<3, 3>(3, 3) = A_R;
  return out;
}

// Node 0 stays where it is: the graph's other nodes are the unknowns, six each.
class Solver {
 public:
  Solver(std::vector<Eigen::Isometry3d>& poses, std::vector<Edge>& edges, double distance_m)
      : poses_(poses), edges_(edges), unknowns_(6 * (static_cast<int>(poses.size()) - 1)) {
    // The line process's weight (Choi et al. 2015, Section 5): the distance squared times the
    // mean correspondence count, which GetInformationMatrixFromPointClouds leaves in (5, 5).
    double correspondences = 0.0;
    for (const Edge& edge : edges_) correspondences += edge.information(5, 5);
    if (!edges_.empty()) {
      mu_ = distance_m * distance_m * correspondences / static_cast<double>(edges_.size());
    }
  }

  void run() {
    if (unknowns_ <= 0 || edges_.empty()) return;
    linearisations_ = lineariseAll(poses_);
    updateConfidence();
    double cost = costOf(linearisations_);
    buildNormalEquations();
    if (b_.cwiseAbs().maxCoeff() < kMinGradient) return;
    // Open3D's start; never zero, so that damping can grow when a factorisation fails.
    double lambda = std::max(1e-5 * H_.diagonal().maxCoeff(), 1e-12);
    double growth = 2.0;
    solver_.analyzePattern(H_);
    for (int iteration = 0; iteration < kMaxIterations && cost >= kMinCost; ++iteration) {
      bool stepped = false;
      for (int tries = 0; tries < kMaxDampingTries && !stepped; ++tries) {
        const Eigen::VectorXd step = solveDamped(lambda);
        if (step.size() == 0) {  // not positive definite: damp more
          lambda *= growth;
          growth *= 2.0;
          continue;
        }
        if (step.norm() < kMinRelativeStep * (stateNorm() + kMinRelativeStep)) return;
        std::vector<Eigen::Isometry3d> moved = movedBy(step);
        std::vector<Linearisation> next = lineariseAll(moved);
        const double next_cost = costOf(next);
        // The model's predicted decrease of the (unhalved) cost is step . (lambda step + b).
        const double gain = (cost - next_cost) / (step.dot(lambda * step + b_) + 1e-3);
        if (gain <= 0.0) {
          lambda *= growth;
          growth *= 2.0;
          continue;
        }
        if (cost - next_cost < kMinRelativeDecrease * cost) return;
        // Nielsen's damping update, bounded to [1/3, 2/3] of lambda as Open3D bounds it.
        lambda *= std::clamp(1.0 - std::pow(2.0 * gain - 1.0, 3), 1.0 / 3.0, 2.0 / 3.0);
        growth = 2.0;
        poses_ = std::move(moved);
        linearisations_ = std::move(next);
        // The line process at its optimum for the new poses lowers the cost further; the next
        // step is judged against the cost it leaves (Open3D keeps the cost before it).
        updateConfidence();
        cost = costOf(linearisations_);
        buildNormalEquations();
        if (b_.cwiseAbs().maxCoeff() < kMinGradient) return;
        stepped = true;
      }
      if (!stepped) return;
    }
  }

  // The loop edges' line process at the poses reached.
  void settleConfidence() {
    linearisations_ = lineariseAll(poses_);
    updateConfidence();
  }

 private:
  std::vector<Linearisation> lineariseAll(const std::vector<Eigen::Isometry3d>& poses) const {
    std::vector<Linearisation> out;
    out.reserve(edges_.size());
    for (const Edge& edge : edges_) out.push_back(linearise(edge, poses));
    return out;
  }

  // Choi et al. 2015, Eq. 9 at the current line process: sum of l e' L e + mu (sqrt(l) - 1)^2.
  double costOf(const std::vector<Linearisation>& linearisations) const {
    double cost = 0.0;
    for (std::size_t i = 0; i < edges_.size(); ++i) {
      const Edge& edge = edges_[i];
      const Vector6d& e = linearisations[i].residual;
      cost += edge.confidence * e.dot(edge.information * e) +
              mu_ * std::pow(std::sqrt(edge.confidence) - 1.0, 2);
    }
    return cost;
  }

  // dE/dl = 0 gives l = (mu / (mu + e' L e))^2 for each loop edge.
  void updateConfidence() {
    for (std::size_t i = 0; i < edges_.size(); ++i) {
      Edge& edge = edges_[i];
      if (!edge.loop) continue;
      const Vector6d& e = linearisations_[i].residual;
      const double ratio = mu_ / (mu_ + e.dot(edge.information * e));
      edge.confidence = ratio * ratio;
    }
  }

  // H = sum of l J' L J and b = -sum of l J' L e over the unknowns (node 0 left out).
  void buildNormalEquations() {
    std::vector<Eigen::Triplet<double>> entries;
    entries.reserve(edges_.size() * 4 * 36 + static_cast<std::size_t>(unknowns_));
    b_ = Eigen::VectorXd::Zero(unknowns_);
    const auto addBlock = [&](int row_node, int col_node, const Matrix6d& block) {
      if (row_node == 0 || col_node == 0) return;
      for (int r = 0; r < 6; ++r) {
        for (int c = 0; c < 6; ++c) {
          entries.emplace_back(6 * (row_node - 1) + r, 6 * (col_node - 1) + c, block(r, c));
        }
      }
    };
    for (std::size_t i = 0; i < edges_.size(); ++i) {
      const Edge& edge = edges_[i];
      const Linearisation& lin = linearisations_[i];
      const Eigen::Matrix<double, 6, 6> JtL =
          edge.confidence * lin.J_source.transpose() * edge.information;
      const Matrix6d block = JtL * lin.J_source;
      addBlock(edge.source, edge.source, block);
      addBlock(edge.target, edge.target, block);
      addBlock(edge.source, edge.target, -block);
      addBlock(edge.target, edge.source, -block);
      const Vector6d g = JtL * lin.residual;
      if (edge.source > 0) b_.segment<6>(6 * (edge.source - 1)) -= g;
      if (edge.target > 0) b_.segment<6>(6 * (edge.target - 1)) += g;
    }
    // Every unknown on the diagonal, so that damping never changes the pattern.
    for (int i = 0; i < unknowns_; ++i) entries.emplace_back(i, i, 0.0);
    H_.resize(unknowns_, unknowns_);
    H_.setFromTriplets(entries.begin(), entries.end());
  }

  // (H + lambda I) step = b; empty when the factorisation fails.
  Eigen::VectorXd solveDamped(double lambda) {
    SparseMatrix damped = H_;
    for (int i = 0; i < unknowns_; ++i) damped.coeffRef(i, i) += lambda;
    solver_.factorize(damped);
    if (solver_.info() != Eigen::Success) return {};
    Eigen::VectorXd step = solver_.solve(b_);
    if (solver_.info() != Eigen::Success || !step.allFinite()) return {};
    return step;
  }

  std::vector<Eigen::Isometry3d> movedBy(const Eigen::VectorXd& step) const {
    std::vector<Eigen::Isometry3d> moved = poses_;
    for (std::size_t node = 1; node < moved.size(); ++node) {
      const Vector6d d = step.segment<6>(6 * (static_cast<Eigen::Index>(node) - 1));
      Eigen::Isometry3d motion = Eigen::Isometry3d::Identity();
      const double angle = d.head<3>().norm();
      if (angle > 0.0) {
        motion.linear() = Eigen::AngleAxisd(angle, d.head<3>() / angle).toRotationMatrix();
      }
      motion.translation() = d.tail<3>();
      moved[node] = motion * moved[node];
    }
    return moved;
  }

  // The unknowns' size as Open3D measures it: each pose's rotation vector and translation.
  double stateNorm() const {
    double squared = 0.0;
    for (std::size_t node = 1; node < poses_.size(); ++node) {
      const Eigen::AngleAxisd rotation(poses_[node].linear());
      squared += (rotation.angle() * rotation.axis()).squaredNorm() +
                 poses_[node].translation().squaredNorm();
    }
    return std::sqrt(squared);
  }

  std::vector<Eigen::Isometry3d>& poses_;
  std::vector<Edge>& edges_;
  int unknowns_;
  double mu_ = 0.0;
  std::vector<Linearisation> linearisations_;
  SparseMatrix H_;
  Eigen::VectorXd b_;
  Eigen::SimplicialLDLT<SparseMatrix> solver_;
};

// Loops whose line process fell to the threshold or below leave the graph.
void pruneLoops(std::vector<Edge>& edges, double edge_prune_threshold) {
  edges.erase(std::remove_if(edges.begin(), edges.end(),
                             [&](const Edge& edge) {
                               return edge.loop && edge.confidence <= edge_prune_threshold;
                             }),
              edges.end());
}

// Solve, prune, solve again and prune again, as Choi et al. 2015 (Section 5) and Open3D do.
void solvePruning(std::vector<Eigen::Isometry3d>& poses, std::vector<Edge>& edges,
                  double distance_m, double edge_prune_threshold) {
  for (int pass = 0; pass < 2; ++pass) {
    Solver solver(poses, edges, distance_m);
    solver.run();
    solver.settleConfidence();
    pruneLoops(edges, edge_prune_threshold);
  }
}

}  // namespace

GraphSolution optimisePoseGraph(const std::vector<core::Isometry>& T_W_C,
                                const std::vector<GraphEdge>& edges, double edge_prune_threshold,
                                double drift_distance_m) {
  const auto start = std::chrono::steady_clock::now();
  std::vector<Edge> graph;
  graph.reserve(edges.size());
  for (const GraphEdge& edge : edges) {
    graph.push_back({edge.source, edge.target, edge.T_target_source.inverse(), edge.information,
                     edge.loop, 1.0, graph.size()});
  }
  std::vector<Eigen::Isometry3d> poses(T_W_C.begin(), T_W_C.end());
  std::vector<Edge> kept = graph;
  if (poses.size() >= 2) {
    // First solve: the drift-sized distance; its poses start the second, on every edge again.
    std::vector<Edge> coarse = graph;
    solvePruning(poses, coarse, std::max(drift_distance_m, kLineProcessDistanceM),
                 edge_prune_threshold);
    solvePruning(poses, kept, kLineProcessDistanceM, edge_prune_threshold);
  }
  GraphSolution out;
  out.T_W_C.assign(poses.begin(), poses.end());
  std::vector<bool> left(graph.size(), false);
  for (const Edge& edge : kept) left[edge.given] = true;
  for (const Edge& edge : graph) {
    if (edge.loop) out.loop_kept.push_back(left[edge.given]);
  }
  out.ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
               .count();
  return out;
}

}  // namespace tessera::loop
