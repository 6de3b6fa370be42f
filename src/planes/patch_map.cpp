#include "tessera/planes/patch_map.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <fmt/format.h>
#include <spdlog/spdlog.h>
#include <Eigen/Geometry>

#include <opencv2/core.hpp>

#include "tessera/core/error.h"

namespace tessera::planes {

std::vector<PlaneObservation> observationsOf(const core::Frame& frame,
                                             const PlaneDetection& detection,
                                             const core::Isometry& T_W_C) {
  const core::Intrinsics& k = frame.intrinsics;
  std::vector<PlaneObservation> observations(detection.planes.size());
  for (PlaneObservation& observation : observations) observation.camera_W = T_W_C.translation();
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

Patch::Frame Patch::planeFrame() const {
  Frame frame;
  frame.origin = origin + (offset - normal.dot(origin)) * normal;
  frame.u_axis = (u_axis - u_axis.dot(normal) * normal).normalized();
  frame.v_axis = normal.cross(frame.u_axis);
  return frame;
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

bool PatchMap::continues(const Patch& patch, const PlaneFit& region,
                         const std::vector<Eigen::Vector3d>& points) const {
  // Planes are compared as unoriented: a region seen from the other side is the same plane.
  const double cos_angle = std::abs(patch.normal.dot(region.normal));
  if (cos_angle < std::cos(config_.max_normal_angle_deg * M_PI / 180.0)) return false;
  // The region's centroid must lie near the patch's plane. (Comparing plane offsets instead
  // would magnify a small tilt by the distance from the world origin.)
  if (std::abs(patch.normal.dot(region.centroid) - patch.offset) > config_.max_offset_m) {
    return false;
  }
  // Touching: a point falls in or next to an occupied cell. Points come in raster order, so
  // a point in the same cell as the one before adds nothing.
  Cell last{std::numeric_limits<int>::min(), 0};
  for (const auto& X : points) {
    const Cell c = patch.cellOf(X, config_.cell_m);
    if (c == last) continue;
    last = c;
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
  Cell last{std::numeric_limits<int>::min(), 0};
  for (const auto& X : points) {
    const Cell c = patch.cellOf(X, config_.cell_m);
    if (c != last) patch.cells.insert(c);
    last = c;
  }
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
  into.footprint_sum_m += other.footprint_sum_m;
  into.footprint_pixels += other.footprint_pixels;
  into.log_gain_sum += other.log_gain_sum;
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
      if (continues(patches_[i], plane, observation.points_W)) {
        matches.push_back(i);
      }
    }
    if (matches.empty()) {
      Patch patch;
      patch.id = next_id_++;
      const double facing =
          plane.normal.dot(observation.camera_W - plane.centroid) > 0.0 ? -1.0 : 1.0;
      patch.normal = facing * plane.normal;
      patch.offset = facing * plane.offset;
      patch.origin = plane.centroid;
      patch.u_axis = plane.major_axis;  // eigenvectors: already orthogonal to the normal
      patch.v_axis = patch.normal.cross(patch.u_axis);
      patch.samples = ColourSamples(config_.sample_cell_m);
      addObservation(patch, observation.points_W, moments);
      patches_.push_back(std::move(patch));
      ids.push_back(patches_.back().id);
      seen_this_frame_.insert(patches_.back().id);
      continue;
    }
    // The region joins every patch it continues: they were parts of one plane.
    for (const std::size_t m : matches) restoreSamples(patches_[m]);
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

PatchSnapshot PatchMap::snapshot(const Patch& patch) const {
  PatchSnapshot snapshot;
  snapshot.id = patch.id;
  snapshot.version = patch.version;
  snapshot.normal = patch.normal;
  snapshot.offset = patch.offset;
  snapshot.frame = patch.planeFrame();
  snapshot.outline = outlineOf(patch);
  snapshot.samples = patch.samples.all();
  if (patch.footprint_pixels > 0 && !patch.log_gain_sum.isZero()) {
    // Samples were compensated to the first frame's exposure; the mean exposure of the frames
    // that coloured the patch fits its views best.
    const Eigen::Vector3d back =
        (-patch.log_gain_sum / static_cast<double>(patch.footprint_pixels)).array().exp();
    for (ColourSample& sample : snapshot.samples) {
      for (int c = 0; c < 3; ++c) {
        const auto i = static_cast<std::size_t>(c);
        sample.rgb[i] = cv::saturate_cast<std::uint8_t>(back[c] * sample.rgb[i]);
      }
    }
  }
  if (patch.footprint_pixels > 0) {
    snapshot.pixel_footprint_m =
        patch.footprint_sum_m / static_cast<double>(patch.footprint_pixels);
  }
  return snapshot;
}

void PatchMap::finalize(Patch& patch, std::vector<PatchEvent>& events) const {
  patch.version += 1;
  patch.finalized = true;
  patch.finalized_area_m2 = areaM2(patch);
  events.push_back(
      {PatchEvent::Kind::kFinalized, patch.id, patch.version, patch.finalized_area_m2});
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
    patch.frames_seen += 1;
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

void PatchMap::setSampleSpillDir(std::filesystem::path dir) {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) {
    spdlog::warn("{}: cannot create it ({}); colour samples stay in memory", dir.string(),
                 ec.message());
    return;
  }
  spill_dir_ = std::move(dir);
}

std::size_t PatchMap::releaseIdleSamples(long frame_index) {
  if (!spill_dir_ || config_.release_samples_after_frames <= 0 || spill_failed_) return 0;
  std::size_t released = 0;
  for (Patch& patch : patches_) {
    if (!patch.finalized || patch.spilled_samples || patch.samples.size() == 0 ||
        frame_index - patch.last_seen_frame < config_.release_samples_after_frames) {
      continue;
    }
    const std::filesystem::path path = *spill_dir_ / fmt::format("patch_{}.samples", patch.id);
    try {
      patch.samples.save(path);
    } catch (const core::Error& e) {
      spdlog::warn("{}; colour samples stay in memory from now on", e.what());
      spill_failed_ = true;
      std::error_code ec;
      std::filesystem::remove(path, ec);
      break;
    }
    patch.samples = ColourSamples(config_.sample_cell_m);
    patch.spilled_samples = path;
    ++released;
  }
  samples_released_ += released;
  return released;
}

void PatchMap::restoreSamples(Patch& patch) const {
  if (!patch.spilled_samples) return;
  try {
    patch.samples = ColourSamples::load(*patch.spilled_samples);
  } catch (const core::Error& e) {  // the patch goes on with the samples it gets from now
    spdlog::error("patch {}: {}; its earlier colours are lost", patch.id, e.what());
  }
  std::error_code ec;
  std::filesystem::remove(*patch.spilled_samples, ec);
  patch.spilled_samples.reset();
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
  return static_cast<std::size_t>(
      std::count_if(patches_.begin(), patches_.end(), [](const Patch& p) { return !p.finalized; }));
}

std::size_t PatchMap::finalizedCount() const { return patches_.size() - liveCount(); }

}  // namespace tessera::planes
