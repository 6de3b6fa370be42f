#include "tessera/planes/patch_map.h"

#include <algorithm>
#include <cmath>

#include <Eigen/Geometry>

namespace tessera::planes {

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

void PatchMap::addObservation(Patch& patch, const std::vector<Eigen::Vector3d>& points,
                              const PointMoments& moments) const {
  for (const auto& X : points) patch.cells.insert(patch.cellOf(X, config_.cell_m));
  patch.moments.add(moments);
  refit(patch);
}

void PatchMap::refit(Patch& patch) {
  const PlaneFit plane = fitPlane(patch.moments);
  // Keep the orientation the patch was created with.
  const double sign = plane.normal.dot(patch.normal) < 0.0 ? -1.0 : 1.0;
  patch.normal = sign * plane.normal;
  patch.offset = sign * plane.offset;
}

void PatchMap::absorb(Patch& into, const Patch& other) const {
  for (const Cell& cell : other.cells) {
    into.cells.insert(into.cellOf(other.cellCentre(cell, config_.cell_m), config_.cell_m));
  }
  into.moments.add(other.moments);
  refit(into);
}

std::vector<int> PatchMap::add(const std::vector<PlaneObservation>& observations) {
  std::vector<int> ids;
  for (const PlaneObservation& observation : observations) {
    if (observation.points_W.size() < 3) {
      ids.push_back(-1);
      continue;
    }
    PointMoments moments;
    for (const auto& X : observation.points_W) moments.add(X);
    const PlaneFit plane = fitPlane(moments);
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
      patch.u_axis = plane.major_axis;  // eigenvectors: already orthogonal to the normal
      patch.v_axis = plane.normal.cross(patch.u_axis);
      addObservation(patch, observation.points_W, moments);
      patches_.push_back(std::move(patch));
      ids.push_back(patches_.back().id);
      continue;
    }
    // The region joins every patch it continues: they were parts of one plane.
    Patch& kept = patches_[matches.front()];
    for (std::size_t m = matches.size(); m-- > 1;) {
      absorb(kept, patches_[matches[m]]);
    }
    addObservation(kept, observation.points_W, moments);
    const int kept_id = kept.id;
    for (std::size_t m = matches.size(); m-- > 1;) {
      patches_.erase(patches_.begin() + static_cast<std::ptrdiff_t>(matches[m]));
    }
    ids.push_back(kept_id);
  }
  return ids;
}

}  // namespace tessera::planes
