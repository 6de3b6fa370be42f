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
  // Samples move into the kept patch's plane frame.
  for (ColourSample sample : other.samples.all()) {
    const Eigen::Vector3d X = other.origin + sample.u * other.u_axis + sample.v * other.v_axis;
    sample.u = static_cast<float>((X - into.origin).dot(into.u_axis));
    sample.v = static_cast<float>((X - into.origin).dot(into.v_axis));
    into.samples.add(sample);
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
      patch.samples = ColourSamples(config_.sample_cell_m, config_.samples_per_cell);
      addObservation(patch, observation.points_W, moments);
      patches_.push_back(std::move(patch));
      ids.push_back(patches_.back().id);
      seen_this_frame_.insert(patches_.back().id);
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
      const Patch& gone = patches_[matches[m]];
      if (gone.version > 0) pending_.push_back({PatchEvent::Kind::kRetired, gone.id, gone.version});
      seen_this_frame_.erase(gone.id);
      // Ids already handed out for this frame's earlier regions now live on in the kept patch.
      std::replace(ids.begin(), ids.end(), gone.id, kept_id);
      patches_.erase(patches_.begin() + static_cast<std::ptrdiff_t>(matches[m]));
    }
    ids.push_back(kept_id);
    seen_this_frame_.insert(kept_id);
  }
  return ids;
}

void PatchMap::addColours(const core::Frame& frame, const PlaneDetection& detection,
                          const core::Isometry& T_W_C, const std::vector<int>& ids) {
  const core::Intrinsics& k = frame.intrinsics;
  if (frame.colour_camera || frame.rgb.type() != CV_8UC3 || frame.rgb.cols != k.width ||
      frame.rgb.rows != k.height) {
    return;  // colour not registered pixel for pixel to depth
  }
  std::vector<Patch*> patch_of_label;
  for (const int id : ids) {
    auto it = std::find_if(patches_.begin(), patches_.end(),
                           [id](const Patch& p) { return p.id == id; });
    patch_of_label.push_back(it == patches_.end() ? nullptr : &*it);
  }
  const Eigen::Matrix3d R = T_W_C.linear();
  const Eigen::Vector3d o = T_W_C.translation();
  const int scale = detection.scale;
  for (int y = 0; y < frame.rgb.rows; ++y) {
    const auto* label = detection.labels.ptr<std::uint8_t>(y / scale);
    const auto* rgb = frame.rgb.ptr<cv::Vec3b>(y);
    for (int x = 0; x < frame.rgb.cols; ++x) {
      const std::uint8_t l = label[x / scale];
      if (l >= patch_of_label.size() || patch_of_label[l] == nullptr) continue;
      Patch& patch = *patch_of_label[l];
      const Eigen::Vector3d ray = R * Eigen::Vector3d((x - k.cx) / k.fx, (y - k.cy) / k.fy, 1.0);
      const double along = patch.normal.dot(ray);
      if (std::abs(along) < 1e-6) continue;
      const double t = (patch.offset - patch.normal.dot(o)) / along;  // ray meets plane
      if (t <= 0.0) continue;
      const Eigen::Vector3d X = o + t * ray;
      const double distance = t * ray.norm();
      ColourSample sample;
      sample.u = static_cast<float>((X - patch.origin).dot(patch.u_axis));
      sample.v = static_cast<float>((X - patch.origin).dot(patch.v_axis));
      sample.rgb = {rgb[x][0], rgb[x][1], rgb[x][2]};
      sample.weight = static_cast<float>(std::abs(along) / ray.norm() / (distance * distance));
      patch.samples.add(sample);
    }
  }
}

void PatchMap::finalize(Patch& patch, std::vector<PatchEvent>& events) const {
  patch.version += 1;
  patch.finalized = true;
  patch.finalized_area_m2 = areaM2(patch);
  events.push_back({PatchEvent::Kind::kFinalized, patch.id, patch.version});
}

std::vector<PatchEvent> PatchMap::endFrame(long frame_index) {
  std::vector<PatchEvent> events = std::move(pending_);
  pending_.clear();
  for (Patch& patch : patches_) {
    const double area = areaM2(patch);
    if (seen_this_frame_.count(patch.id) == 0) {
      const bool gone_long = frame_index - patch.last_seen_frame >= config_.out_of_view_frames;
      if (!patch.finalized && gone_long && area >= config_.min_area_m2) finalize(patch, events);
      continue;
    }
    patch.last_seen_frame = frame_index;
    patch.area_in_view.push_back(area);
    while (patch.area_in_view.size() > static_cast<std::size_t>(config_.stable_frames) + 1) {
      patch.area_in_view.pop_front();
    }
    if (patch.finalized && area > patch.finalized_area_m2 * (1.0 + config_.max_growth)) {
      patch.finalized = false;  // it grows again: a new version will follow
    }
    const bool stable =
        patch.area_in_view.size() > static_cast<std::size_t>(config_.stable_frames) &&
        area <= patch.area_in_view.front() * (1.0 + config_.max_growth);
    if (!patch.finalized && stable && area >= config_.min_area_m2) finalize(patch, events);
  }
  seen_this_frame_.clear();
  return events;
}

std::vector<PatchEvent> PatchMap::finalizeAll() {
  std::vector<PatchEvent> events = std::move(pending_);
  pending_.clear();
  for (Patch& patch : patches_) {
    if (!patch.finalized && areaM2(patch) >= config_.min_area_m2) finalize(patch, events);
  }
  return events;
}

const Patch* PatchMap::find(int id) const {
  for (const Patch& patch : patches_) {
    if (patch.id == id) return &patch;
  }
  return nullptr;
}

std::size_t PatchMap::liveCount() const {
  return static_cast<std::size_t>(std::count_if(patches_.begin(), patches_.end(),
                                                [](const Patch& p) { return !p.finalized; }));
}

std::size_t PatchMap::finalizedCount() const { return patches_.size() - liveCount(); }

}  // namespace tessera::planes
