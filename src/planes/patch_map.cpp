#include "tessera/planes/patch_map.h"

#include <algorithm>
#include <cmath>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>

namespace tessera::planes {

namespace {

struct FittedPlane {
  Eigen::Vector3d normal;
  double offset;
  Eigen::Vector3d centroid;
  Eigen::Vector3d major_axis;  // direction of largest spread
};

// Least squares from moments: the centroid and the scatter matrix's smallest eigenvector.
FittedPlane fit(double count, const Eigen::Vector3d& sum, const Eigen::Matrix3d& outer) {
  FittedPlane plane;
  plane.centroid = sum / count;
  const Eigen::Matrix3d scatter = outer / count - plane.centroid * plane.centroid.transpose();
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver(scatter);
  plane.normal = solver.eigenvectors().col(0);
  plane.major_axis = solver.eigenvectors().col(2);
  plane.offset = plane.normal.dot(plane.centroid);
  return plane;
}

FittedPlane fitPoints(const std::vector<Eigen::Vector3d>& points) {
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  Eigen::Matrix3d outer = Eigen::Matrix3d::Zero();
  for (const auto& X : points) sum += X, outer += X * X.transpose();
  return fit(static_cast<double>(points.size()), sum, outer);
}

}  // namespace

std::vector<PlaneObservation> observationsOf(const core::Frame& frame,
                                             const PlaneDetection& detection,
                                             const core::Isometry& T_W_C) {
  const core::Intrinsics& k = frame.intrinsics;
  std::vector<PlaneObservation> observations(detection.planes.size());
  const int step = detection.scale;
  for (int v = 0; v < detection.labels.rows; ++v) {
    const auto* label = detection.labels.ptr<std::uint8_t>(v);
    const auto* depth = frame.depth_mm.ptr<std::uint16_t>(v * step);
    for (int u = 0; u < detection.labels.cols; ++u) {
      if (label[u] >= observations.size()) continue;
      const double z = depth[u * step] * 1e-3;
      const Eigen::Vector3d X_C((u * step - k.cx) * z / k.fx, (v * step - k.cy) * z / k.fy, z);
      observations[label[u]].points_W.push_back(T_W_C * X_C);
    }
  }
  return observations;
}

Cell Patch::cellOf(const Eigen::Vector3d& X_W, double cell_m) const {
  const Eigen::Vector3d d = X_W - origin;
  return {static_cast<int>(std::floor(d.dot(u_axis) / cell_m)),
          static_cast<int>(std::floor(d.dot(v_axis) / cell_m))};
}

Eigen::Vector3d Patch::cellCentre(const Cell& cell, double cell_m) const {
  return origin + (cell.first + 0.5) * cell_m * u_axis + (cell.second + 0.5) * cell_m * v_axis;
}

double PatchMap::areaM2(const Patch& patch) const {
  return static_cast<double>(patch.cells.size()) * config_.cell_m * config_.cell_m;
}

bool PatchMap::continues(const Patch& patch, const Eigen::Vector3d& normal, double offset,
                         const std::vector<Eigen::Vector3d>& points) const {
  // Planes are compared as unoriented: a region seen from the other side is the same plane.
  const double cos_angle = std::abs(patch.normal.dot(normal));
  if (cos_angle < std::cos(config_.max_normal_angle_deg * M_PI / 180.0)) return false;
  const double sign = patch.normal.dot(normal) < 0.0 ? -1.0 : 1.0;
  if (std::abs(sign * offset - patch.offset) > config_.max_offset_m) return false;
  // Touching: a point falls in or next to an occupied cell.
  for (const auto& X : points) {
    const Cell c = patch.cellOf(X, config_.cell_m);
    for (int du = -1; du <= 1; ++du) {
      for (int dv = -1; dv <= 1; ++dv) {
        if (patch.cells.count({c.first + du, c.second + dv}) > 0) return true;
      }
    }
  }
  return false;
}

void PatchMap::addPoints(Patch& patch, const std::vector<Eigen::Vector3d>& points) const {
  for (const auto& X : points) {
    patch.cells.insert(patch.cellOf(X, config_.cell_m));
    patch.point_count += 1.0;
    patch.point_sum += X;
    patch.point_outer += X * X.transpose();
  }
  const FittedPlane plane = fit(patch.point_count, patch.point_sum, patch.point_outer);
  // Keep the orientation the patch was created with.
  const double sign = plane.normal.dot(patch.normal) < 0.0 ? -1.0 : 1.0;
  patch.normal = sign * plane.normal;
  patch.offset = sign * plane.offset;
}

void PatchMap::absorb(Patch& into, const Patch& other) const {
  for (const Cell& cell : other.cells) {
    into.cells.insert(into.cellOf(other.cellCentre(cell, config_.cell_m), config_.cell_m));
  }
  into.point_count += other.point_count;
  into.point_sum += other.point_sum;
  into.point_outer += other.point_outer;
  addPoints(into, {});  // refit from the summed moments
}

std::vector<int> PatchMap::add(const std::vector<PlaneObservation>& observations) {
  std::vector<int> ids;
  for (const PlaneObservation& observation : observations) {
    if (observation.points_W.size() < 3) {
      ids.push_back(-1);
      continue;
    }
    const FittedPlane plane = fitPoints(observation.points_W);
    std::vector<std::size_t> matches;
    for (std::size_t i = 0; i < patches_.size(); ++i) {
      if (continues(patches_[i], plane.normal, plane.offset, observation.points_W)) {
        matches.push_back(i);
      }
    }
    if (matches.empty()) {
      Patch patch;
      patch.id = next_id_++;
      patch.normal = plane.normal;
      patch.offset = plane.offset;
      patch.origin = plane.centroid;
      patch.u_axis =
          (plane.major_axis - plane.major_axis.dot(plane.normal) * plane.normal).normalized();
      patch.v_axis = plane.normal.cross(patch.u_axis);
      addPoints(patch, observation.points_W);
      patches_.push_back(std::move(patch));
      ids.push_back(patches_.back().id);
      continue;
    }
    // The region joins every patch it continues: they were parts of one plane.
    Patch& kept = patches_[matches.front()];
    for (std::size_t m = matches.size(); m-- > 1;) {
      absorb(kept, patches_[matches[m]]);
    }
    addPoints(kept, observation.points_W);
    const int kept_id = kept.id;
    for (std::size_t m = matches.size(); m-- > 1;) {
      patches_.erase(patches_.begin() + static_cast<std::ptrdiff_t>(matches[m]));
    }
    ids.push_back(kept_id);
  }
  return ids;
}

}  // namespace tessera::planes
