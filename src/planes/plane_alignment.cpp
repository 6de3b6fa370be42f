#include "tessera/planes/plane_alignment.h"

#include <algorithm>
#include <cmath>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>

namespace tessera::planes {

namespace {

struct PlaneTerm {
  Eigen::Vector3d normal;
  double offset;
  std::vector<Eigen::Vector3d> points;  // world points, at the current estimate
};

const Patch* anchorFor(const PatchMap& map, const PlaneObservation& observation,
                       const PlaneAlignmentConfig& config) {
  PointMoments moments;
  for (const auto& X : observation.points_W) moments.add(X);
  const PlaneFit region = fitPlane(moments);
  for (const Patch& patch : map.patches()) {
    if (patch.frames_seen < config.min_patch_frames) continue;
    if (map.areaM2(patch) < config.min_patch_area_m2) continue;
    if (map.continues(patch, region, observation.points_W)) return &patch;
  }
  return nullptr;
}

// Small rigid motion exp([w, v]) applied on the left, to first order plus the exact rotation.
core::Isometry motionOf(const Eigen::Matrix<double, 6, 1>& step) {
  core::Isometry D = core::Isometry::Identity();
  const Eigen::Vector3d w = step.head<3>();
  if (w.norm() > 0.0) D.linear() = Eigen::AngleAxisd(w.norm(), w.normalized()).toRotationMatrix();
  D.translation() = step.tail<3>();
  return D;
}

}  // namespace

std::optional<core::Isometry> alignToPatches(const PatchMap& map,
                                             const std::vector<PlaneObservation>& observations_W,
                                             const Eigen::Vector3d& camera_centre_W,
                                             const PlaneAlignmentConfig& config) {
  if (!config.enabled) return std::nullopt;
  std::vector<PlaneTerm> terms;
  for (const PlaneObservation& observation : observations_W) {
    if (observation.points_W.size() < 3) continue;
    const Patch* anchor = anchorFor(map, observation, config);
    if (anchor == nullptr) continue;
    PlaneTerm term{anchor->normal(), anchor->offset(), {}};
    const std::size_t stride =
        std::max<std::size_t>(1, observation.points_W.size() / config.points_per_region);
    for (std::size_t i = 0; i < observation.points_W.size(); i += stride) {
      term.points.push_back(observation.points_W[i]);
    }
    terms.push_back(std::move(term));
  }
  if (terms.empty()) return std::nullopt;

  // Gauss-Newton on r = n . (D X) - d, D a rotation about the camera centre c and a
  // translation: D X = c + exp([w]) (X - c) + v, so dr/dw = (X - c) x n and dr/dv = n.
  // Each plane's terms are weighted by 1 / (its point count), so a big wall does not drown
  // the table.
  const Eigen::Vector3d c = camera_centre_W;
  core::Isometry D = core::Isometry::Identity();
  for (int iteration = 0; iteration < 3; ++iteration) {
    Eigen::Matrix<double, 6, 6> H = Eigen::Matrix<double, 6, 6>::Zero();
    Eigen::Matrix<double, 6, 1> g = Eigen::Matrix<double, 6, 1>::Zero();
    for (const PlaneTerm& term : terms) {
      const double weight = 1.0 / static_cast<double>(term.points.size());
      for (const Eigen::Vector3d& X0 : term.points) {
        const Eigen::Vector3d X = D * X0;
        const double r = term.normal.dot(X) - term.offset;
        Eigen::Matrix<double, 6, 1> J;
        J << (X - c).cross(term.normal), term.normal;
        H += weight * J * J.transpose();
        g += weight * J * r;
      }
    }
    // Solve in the eigenbasis of H, leaving out directions the planes do not constrain.
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 6, 6>> solver(H);
    const double largest = solver.eigenvalues().maxCoeff();
    Eigen::Matrix<double, 6, 1> step = Eigen::Matrix<double, 6, 1>::Zero();
    for (int i = 0; i < 6; ++i) {
      const double lambda = solver.eigenvalues()(i);
      if (lambda < 1e-3 * largest) continue;
      const Eigen::Matrix<double, 6, 1> e = solver.eigenvectors().col(i);
      step -= e * (e.dot(g) / lambda);
    }
    core::Isometry about_centre = core::Isometry::Identity();
    about_centre.translation() = c;
    D = about_centre * motionOf(step) * about_centre.inverse() * D;
  }
  const double angle_deg = Eigen::AngleAxisd(D.linear()).angle() * 180.0 / M_PI;
  // How far the correction moves the camera (D's own translation would include the lever arm
  // of a rotation about the world origin).
  if ((D * c - c).norm() > config.max_step_m || angle_deg > config.max_step_deg) {
    return std::nullopt;
  }
  return D;
}

}  // namespace tessera::planes
