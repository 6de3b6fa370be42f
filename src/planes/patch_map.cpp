#include "tessera/planes/patch_map.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <stdexcept>

#include <fmt/format.h>
#include <Eigen/Geometry>

#include <opencv2/core.hpp>

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
                         const std::vector<Eigen::Vector3d>& points, double extra_offset_m) const {
  // Planes are compared as unoriented: a region seen from the other side is the same plane.
  const double cos_angle = std::abs(patch.normal.dot(region.normal));
  if (cos_angle < std::cos(config_.max_normal_angle_deg * M_PI / 180.0)) return false;
  // The region's centroid must lie near the patch's plane. (Comparing plane offsets instead
  // would magnify a small tilt by the distance from the world origin.)
  if (std::abs(patch.normal.dot(region.centroid) - patch.offset) >
      config_.max_offset_m + extra_offset_m) {
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

namespace {

int& axis(Cell& cell, int a) { return a == 0 ? cell.first : cell.second; }
int axis(const Cell& cell, int a) { return a == 0 ? cell.first : cell.second; }

int floorDiv(int a, int b) { return a >= 0 ? a / b : -((-a + b - 1) / b); }

}  // namespace

Cell TileGrid::keyOf(const Cell& cell) const {
  Cell key{0, 0};
  for (int a = 0; a < 2; ++a) {
    if (anchor[a]) axis(key, a) = floorDiv(axis(cell, a) - *anchor[a], tile_cells);
  }
  return key;
}

Patch& PatchMap::patchWithId(int id) {
  const auto it =
      std::find_if(patches_.begin(), patches_.end(), [&](const Patch& p) { return p.id == id; });
  // Callers name patches the map holds: anything else is a bug, reported rather than undefined.
  if (it == patches_.end()) throw std::logic_error(fmt::format("patch map: no patch {}", id));
  return *it;
}

Patch& PatchMap::tileAt(int plane_id, const Cell& key) {
  for (Patch& patch : patches_) {
    if (patch.plane == plane_id && patch.tile == key) return patch;
  }
  const Patch& first = patchWithId(plane_id);
  Patch tile;
  tile.id = next_id_++;
  tile.plane = plane_id;
  tile.tile = key;
  tile.normal = first.normal;
  tile.offset = first.offset;
  tile.origin = first.origin;
  tile.u_axis = first.u_axis;
  tile.v_axis = first.v_axis;
  tile.samples = ColourSamples(config_.sample_cell_m);
  patches_.push_back(std::move(tile));
  return patches_.back();
}

void PatchMap::extendGrid(PlaneState& plane, const std::vector<Cell>& cells) const {
  if (cells.empty()) return;
  Cell lo = cells.front(), hi = cells.front();
  for (const Cell& c : cells) {
    for (int a = 0; a < 2; ++a) {
      axis(lo, a) = std::min(axis(lo, a), axis(c, a));
      axis(hi, a) = std::max(axis(hi, a), axis(c, a));
    }
  }
  const int size = plane.grid.tile_cells;
  for (int a = 0; a < 2; ++a) {
    const int old_lo = axis(plane.lo, a), old_hi = axis(plane.hi, a);
    const int new_lo = plane.has_cells ? std::min(old_lo, axis(lo, a)) : axis(lo, a);
    const int new_hi = plane.has_cells ? std::max(old_hi, axis(hi, a)) : axis(hi, a);
    if (size > 0 && !plane.grid.anchor[a] && new_hi - new_lo + 1 > size) {
      // The tile that held the whole plane so far stays tile 0: it spans at most one tile.
      if (!plane.has_cells || new_hi >= old_lo + size) {
        plane.grid.anchor[a] = plane.has_cells ? old_lo : new_lo;
      } else {
        plane.grid.anchor[a] = old_hi + 1 - size;
      }
    }
    axis(plane.lo, a) = new_lo;
    axis(plane.hi, a) = new_hi;
  }
  plane.has_cells = true;
}

int PatchMap::placeCells(int plane_id, const std::vector<Cell>& cells) {
  PlaneState& plane = planes_.at(plane_id);
  extendGrid(plane, cells);
  std::map<Cell, std::vector<Cell>> by_tile;
  for (const Cell& c : cells) by_tile[plane.grid.keyOf(c)].push_back(c);
  int most_id = plane_id;
  std::size_t most = 0;
  for (const auto& [key, tile_cells] : by_tile) {
    Patch& tile = tileAt(plane_id, key);
    restoreSamples(tile);
    tile.cells.insert(tile_cells.begin(), tile_cells.end());
    seen_this_frame_.insert(tile.id);
    if (tile_cells.size() > most) {
      most = tile_cells.size();
      most_id = tile.id;
    }
  }
  return most_id;
}

int PatchMap::placePoints(int plane_id, const std::vector<Eigen::Vector3d>& points,
                          const PointMoments& moments) {
  std::vector<Cell> cells;
  {
    const Patch& first = patchWithId(plane_id);
    Cell last{std::numeric_limits<int>::min(), 0};
    for (const auto& X : points) {
      const Cell c = first.cellOf(X, config_.cell_m);
      if (c != last) cells.push_back(c);  // points come in raster order
      last = c;
    }
  }
  const int id = placeCells(plane_id, cells);
  planes_.at(plane_id).moments.add(moments);
  refitPlane(plane_id);
  return id;
}

void PatchMap::refitPlane(int plane_id) {
  const PlaneFit fit = fitPlane(planes_.at(plane_id).moments);
  // Keep the orientation the plane was created with.
  const double sign = fit.normal.dot(patchWithId(plane_id).normal) < 0.0 ? -1.0 : 1.0;
  for (Patch& tile : patches_) {
    if (tile.plane != plane_id) continue;
    tile.normal = sign * fit.normal;
    tile.offset = sign * fit.offset;
  }
}

std::set<int> PatchMap::mergePlane(int into_id, int from_id, std::vector<int>& ids) {
  std::set<int> took;
  std::vector<Patch> from;
  for (auto it = patches_.begin(); it != patches_.end();) {
    if (it->plane != from_id) {
      ++it;
      continue;
    }
    from.push_back(std::move(*it));
    it = patches_.erase(it);
  }
  PlaneState& into = planes_.at(into_id);
  into.moments.add(planes_.at(from_id).moments);
  // A keyframe both planes had has the same motion in both: both followed every correction.
  for (const auto& [keyframe_ns, observer] : planes_.at(from_id).observers) {
    into.observers[keyframe_ns].points += observer.points;
    into.observers[keyframe_ns].motion = observer.motion;
  }
  planes_.erase(from_id);

  for (Patch& gone : from) {
    restoreSamples(gone);
    if (gone.version > 0) pending_.push_back({PatchEvent::Kind::kRetired, gone.id, gone.version});
    seen_this_frame_.erase(gone.id);
    // The receiving plane's frame, copied: placing cells may add tiles, which moves patches.
    const Patch frame = [&] {
      const Patch& first = patchWithId(into_id);
      Patch copy;
      copy.origin = first.origin;
      copy.u_axis = first.u_axis;
      copy.v_axis = first.v_axis;
      return copy;
    }();
    std::vector<Cell> cells;
    cells.reserve(gone.cells.size());
    for (const Cell& cell : gone.cells) {
      cells.push_back(frame.cellOf(gone.cellCentre(cell, config_.cell_m), config_.cell_m));
    }
    const int took_most = placeCells(into_id, cells);
    took.insert(took_most);
    Patch& heir = patchWithId(took_most);
    heir.footprint_sum_m += gone.footprint_sum_m;
    heir.footprint_pixels += gone.footprint_pixels;
    heir.log_gain_sum += gone.log_gain_sum;
    std::replace(ids.begin(), ids.end(), gone.id, took_most);

    // Samples move into the receiving plane's frame and tiles; one where no tile has a cell
    // shows nothing of the plane and is dropped.
    const TileGrid& grid = planes_.at(into_id).grid;
    std::map<Cell, Patch*> tiles;
    for (Patch& tile : patches_) {
      if (tile.plane == into_id && !tile.spilled_samples) tiles[tile.tile] = &tile;
    }
    for (ColourSample sample : gone.samples.all()) {
      const Eigen::Vector3d X = gone.origin + sample.u * gone.u_axis + sample.v * gone.v_axis;
      sample.u = static_cast<float>((X - frame.origin).dot(frame.u_axis));
      sample.v = static_cast<float>((X - frame.origin).dot(frame.v_axis));
      const Cell cell{static_cast<int>(std::floor(sample.u / config_.cell_m)),
                      static_cast<int>(std::floor(sample.v / config_.cell_m))};
      if (const auto it = tiles.find(grid.keyOf(cell)); it != tiles.end()) {
        it->second->samples.add(sample);
        took.insert(it->second->id);
      }
    }
    // Cells placed in other tiles than the one that took most.
    for (const Cell& cell : cells) {
      if (const auto it = tiles.find(grid.keyOf(cell)); it != tiles.end()) {
        took.insert(it->second->id);
      }
    }
  }
  refitPlane(into_id);
  return took;
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
    // The planes the region continues, oldest first (one touching tile each is enough).
    std::vector<int> planes;
    for (const Patch& patch : patches_) {
      if (std::find(planes.begin(), planes.end(), patch.plane) != planes.end()) continue;
      if (continues(patch, plane, observation.points_W)) planes.push_back(patch.plane);
    }
    if (planes.empty()) {
      Patch patch;
      patch.id = next_id_++;
      patch.plane = patch.id;
      const double facing =
          plane.normal.dot(observation.camera_W - plane.centroid) > 0.0 ? -1.0 : 1.0;
      patch.normal = facing * plane.normal;
      patch.offset = facing * plane.offset;
      patch.origin = plane.centroid;
      patch.u_axis = plane.major_axis;  // eigenvectors: already orthogonal to the normal
      patch.v_axis = patch.normal.cross(patch.u_axis);
      patch.samples = ColourSamples(config_.sample_cell_m);
      PlaneState& state = planes_[patch.id];
      if (config_.tile_m > 0.0) {
        state.grid.tile_cells =
            std::max(1, static_cast<int>(std::lround(config_.tile_m / config_.cell_m)));
      }
      planes.push_back(patch.id);
      patches_.push_back(std::move(patch));
    }
    // The region joins every plane it continues: they were parts of one plane.
    const int kept = planes.front();
    for (std::size_t m = planes.size(); m-- > 1;) mergePlane(kept, planes[m], ids);
    ids.push_back(placePoints(kept, observation.points_W, moments));
    if (observation.keyframe_ns) {
      PlaneState::Observer& observer = planes_.at(kept).observers[*observation.keyframe_ns];
      observer.points += static_cast<double>(observation.points_W.size());
      observer.motion = observation.loop_motion;
    }
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
