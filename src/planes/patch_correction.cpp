// PatchMap after a loop closure: planes move with the keyframes they were seen from, and a
// place mapped twice (once before the drift, once after) becomes one plane again.
#include <algorithm>
#include <cmath>
#include <optional>
#include <utility>
#include <vector>

#include <Eigen/Geometry>

#include "tessera/planes/patch_map.h"

namespace tessera::planes {

namespace {

// A move below these is left alone: it changes no cell, and moving would cost re-association.
constexpr double kMinMove_m = 0.002;
constexpr double kMinTurn_deg = 0.05;

}  // namespace

std::size_t PatchMap::followCorrection(
    const std::function<core::Isometry(std::int64_t keyframe_ns)>& motion_at) {
  std::size_t moved_planes = 0;
  for (auto& [plane_id, plane] : planes_) {
    if (plane.moments.count < 1.0 || plane.observers.empty()) continue;
    const Eigen::Vector3d centroid = plane.moments.sum / plane.moments.count;
    // Each keyframe's move, as a turn and where it takes the centroid, averaged by points.
    Eigen::Vector3d shift = Eigen::Vector3d::Zero();
    Eigen::Vector4d turn = Eigen::Vector4d::Zero();  // quaternion coefficients, summed
    double weight = 0.0;
    bool any = false;
    for (auto& [keyframe_ns, observer] : plane.observers) {
      const core::Isometry target = motion_at(keyframe_ns);
      const core::Isometry step = target * observer.motion.inverse();
      observer.motion = target;
      any = any || step.translation().norm() >= kMinMove_m ||
            core::rotationAngleDeg(step) >= kMinTurn_deg;
      Eigen::Vector4d q = Eigen::Quaterniond(step.linear()).coeffs();
      if (q.w() < 0.0) q = -q;  // one hemisphere: the turns are small
      shift += observer.points * (step * centroid - centroid);
      turn += observer.points * q;
      weight += observer.points;
    }
    if (!any || weight <= 0.0) continue;
    // X -> R (X - c) + c + shift: the centroid moves by the mean shift, the plane turns about it.
    const Eigen::Matrix3d R = Eigen::Quaterniond(Eigen::Vector4d(turn / weight)).normalized()
                                  .toRotationMatrix();
    core::Isometry motion = core::Isometry::Identity();
    motion.linear() = R;
    motion.translation() = centroid + shift / weight - R * centroid;
    plane.move(motion);
    ++moved_planes;
  }
  return moved_planes;
}

std::optional<std::pair<int, int>> PatchMap::findCoinciding() const {
  // Newest plane first, into the oldest it continues.
  for (auto newer = planes_.rbegin(); newer != planes_.rend(); ++newer) {
    const int from_id = newer->first;
    if (newer->second.moments.count < 3.0 || set_aside_.count(from_id) > 0) continue;
    const PlaneFit fit = fitPlane(newer->second.moments);
    std::vector<Eigen::Vector3d> centres;
    for (const auto& [key, id] : newer->second.tiles) {
      const Patch& tile = patches_.at(id);
      for (const Cell& cell : tile.cells) centres.push_back(tile.cellCentre(cell, config_.cell_m));
    }
    for (const auto& [into_id, older] : planes_) {
      if (into_id >= from_id) break;
      if (older.moments.count < 3.0 || set_aside_.count(into_id) > 0) continue;
      // The allowance for a bent plane grows with the distance from where the older plane's
      // fit is anchored (its centroid).
      const double bend_m = std::tan(config_.merge_bend_deg * M_PI / 180.0) *
                            (fit.centroid - fitPlane(older.moments).centroid).norm();
      const bool continued = std::any_of(
          older.tiles.begin(), older.tiles.end(), [&](const std::pair<const Cell, int>& tile) {
            return continues(patches_.at(tile.second), fit, centres, bend_m);
          });
      if (continued) return std::make_pair(into_id, from_id);
    }
  }
  return std::nullopt;
}

std::size_t PatchMap::mergeCoinciding() {
  std::size_t merged = 0;
  std::vector<int> no_ids;
  // One pair at a time: the grown plane may now continue another.
  while (const auto pair = findCoinciding()) {
    for (const int id : mergePlane(pair->first, pair->second, no_ids)) {
      patchWithId(id).finalized = false;  // grows a new version from the merged samples
    }
    ++merged;
  }
  return merged;
}

}  // namespace tessera::planes
