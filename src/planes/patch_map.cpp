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

double PatchMap::areaM2(const Patch& patch) const {
  return static_cast<double>(patch.cells.size()) * config_.cell_m * config_.cell_m;
}

bool PatchMap::continues(const Patch& patch, const PlaneFit& region,
                         const std::vector<Eigen::Vector3d>& points, double extra_offset_m) const {
  // Planes are compared as unoriented: a region seen from the other side is the same plane.
  const double cos_angle = std::abs(patch.normal().dot(region.normal));
  if (cos_angle < std::cos(config_.max_normal_angle_deg * M_PI / 180.0)) return false;
  // The region's centroid must lie near the patch's plane. (Comparing plane offsets instead
  // would magnify a small tilt by the distance from the world origin.)
  if (std::abs(patch.normal().dot(region.centroid) - patch.offset()) >
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

Patch& PatchMap::patchWithId(int id) {
  const auto it = patches_.find(id);
  // Callers name patches the map holds: anything else is a bug, reported rather than undefined.
  if (it == patches_.end()) throw std::logic_error(fmt::format("patch map: no patch {}", id));
  return it->second;
}

std::vector<Patch*> PatchMap::tilesOf(const Plane& plane) {
  std::vector<Patch*> tiles;
  for (const auto& [key, id] : plane.tiles) tiles.push_back(&patchWithId(id));
  std::sort(tiles.begin(), tiles.end(),
            [](const Patch* a, const Patch* b) { return a->id < b->id; });
  return tiles;
}

Patch& PatchMap::tileAt(int plane_id, const Cell& key) {
  Plane& plane = planes_.at(plane_id);
  if (const auto it = plane.tiles.find(key); it != plane.tiles.end())
    return patchWithId(it->second);
  Patch tile;
  tile.id = next_id_++;
  tile.plane = plane_id;
  tile.tile = key;
  tile.geometry = plane.geometry;
  tile.samples = ColourSamples(config_.sample_cell_m, config_.sample_views);
  plane.tiles[key] = tile.id;
  return patches_.emplace(tile.id, std::move(tile)).first->second;
}

int PatchMap::placeCells(int plane_id, const std::vector<Cell>& cells) {
  Plane& plane = planes_.at(plane_id);
  plane.extendGrid(cells);
  std::map<Cell, std::vector<Cell>> by_tile;
  for (const Cell& c : cells) by_tile[plane.grid.keyOf(c)].push_back(c);
  // Without cells, the plane's first tile.
  int most_id = plane.tiles.empty() ? -1 : tilesOf(plane).front()->id;
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
                          const PointMoments& moments, std::optional<std::int64_t> keyframe_ns) {
  std::vector<Cell> cells;
  std::vector<float> counts;  // points per entry of `cells`
  {
    const PlaneGeometry& geometry = *planes_.at(plane_id).geometry;
    Cell last{std::numeric_limits<int>::min(), 0};
    for (const auto& X : points) {
      const Cell c = geometry.cellOf(X, config_.cell_m);
      if (c != last) {  // points come in raster order
        cells.push_back(c);
        counts.push_back(0.0F);
      }
      counts.back() += 1.0F;
      last = c;
    }
  }
  const int id = placeCells(plane_id, cells);
  Plane& plane = planes_.at(plane_id);
  if (keyframe_ns && config_.move_within_plane) {
    std::map<Cell, float> by_block;
    for (std::size_t i = 0; i < cells.size(); ++i) by_block[Plane::blockOf(cells[i])] += counts[i];
    for (const auto& [block, count] : by_block) plane.addSource(block, *keyframe_ns, count);
  }
  plane.moments.add(moments);
  plane.refit();
  return id;
}

std::set<int> PatchMap::mergePlane(int into_id, int from_id, std::vector<int>& ids) {
  // Moves still owed within either plane are made first, in its own frame.
  finishMovesWithin(from_id);
  finishMovesWithin(into_id);
  std::set<int> took;
  std::vector<Patch> from;  // in id order
  for (const Patch* tile : tilesOf(planes_.at(from_id)))
    from.push_back(std::move(patchWithId(tile->id)));
  for (const Patch& gone : from) patches_.erase(gone.id);
  Plane& into = planes_.at(into_id);
  into.moments.add(planes_.at(from_id).moments);
  // A keyframe both planes had has the same motion in both: both followed every correction.
  for (const auto& [keyframe_ns, observer] : planes_.at(from_id).observers) {
    into.observers[keyframe_ns].points += observer.points;
    into.observers[keyframe_ns].motion = observer.motion;
  }
  {
    // Each block's keyframes go to the receiving plane's block at the same place.
    const PlaneGeometry& was = *planes_.at(from_id).geometry;
    const double block_m = Plane::kBlockCells * config_.cell_m;
    for (const auto& [key, block] : planes_.at(from_id).blocks) {
      const Eigen::Vector3d centre = was.origin + (key.first + 0.5) * block_m * was.u_axis +
                                     (key.second + 0.5) * block_m * was.v_axis;
      const Cell to = Plane::blockOf(into.geometry->cellOf(centre, config_.cell_m));
      for (const Plane::Source& source : block.sources) {
        into.addSource(to, source.keyframe_ns, source.points);
      }
    }
  }
  planes_.erase(from_id);

  for (Patch& gone : from) {
    restoreSamples(gone);
    if (gone.version > 0) pending_.push_back({PatchEvent::Kind::kRetired, gone.id, gone.version});
    seen_this_frame_.erase(gone.id);
    const PlaneGeometry frame = *into.geometry;  // the receiving plane's
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
    const TileGrid& grid = into.grid;
    std::map<Cell, Patch*> tiles;
    for (const auto& [key, id] : into.tiles) {
      Patch& tile = patchWithId(id);
      if (!tile.spilled_samples) tiles[key] = &tile;
    }
    const PlaneGeometry& was = *gone.geometry;
    // Only the tiles that take samples change (a texturing job may hold the others' samples).
    std::set<Patch*> sampled;
    for (ColourSample sample : gone.samples->all()) {
      const Eigen::Vector3d X = was.origin + sample.u * was.u_axis + sample.v * was.v_axis;
      sample.u = static_cast<float>((X - frame.origin).dot(frame.u_axis));
      sample.v = static_cast<float>((X - frame.origin).dot(frame.v_axis));
      const Cell cell{static_cast<int>(std::floor(sample.u / config_.cell_m)),
                      static_cast<int>(std::floor(sample.v / config_.cell_m))};
      if (const auto it = tiles.find(grid.keyOf(cell)); it != tiles.end()) {
        it->second->samples.edit().add(sample);
        took.insert(it->second->id);
        sampled.insert(it->second);
      }
    }
    for (Patch* tile : sampled) tile->samples.edit().settle();
    // Cells placed in other tiles than the one that took most.
    for (const Cell& cell : cells) {
      if (const auto it = tiles.find(grid.keyOf(cell)); it != tiles.end()) {
        took.insert(it->second->id);
      }
    }
  }
  into.refit();
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
    for (const auto& [id, patch] : patches_) {
      if (std::find(planes.begin(), planes.end(), patch.plane) != planes.end() ||
          set_aside_.count(patch.plane) > 0) {
        continue;
      }
      if (continues(patch, plane, observation.points_W)) planes.push_back(patch.plane);
    }
    if (planes.empty()) {
      Plane& created = planes_[next_plane_id_];
      created.id = next_plane_id_++;
      PlaneGeometry& geometry = *created.geometry;
      const double facing =
          plane.normal.dot(observation.camera_W - plane.centroid) > 0.0 ? -1.0 : 1.0;
      geometry.normal = facing * plane.normal;
      geometry.offset = facing * plane.offset;
      geometry.origin = plane.centroid;
      geometry.u_axis = plane.major_axis;  // eigenvectors: already orthogonal to the normal
      geometry.v_axis = geometry.normal.cross(geometry.u_axis);
      if (config_.tile_m > 0.0) {
        created.grid.tile_cells =
            std::max(1, static_cast<int>(std::lround(config_.tile_m / config_.cell_m)));
      }
      tileAt(created.id, {0, 0});  // its first tile, which holds the whole plane until it is cut
      planes.push_back(created.id);
    }
    // The region joins every plane it continues: they were parts of one plane. Not while one
    // of the others still waits for moves within it (a correction's, spread over frames):
    // merging now would make all of them in this frame. They merge once moved
    // (mergeCoinciding, or a later region).
    const int kept = planes.front();
    // The plane the points go to makes its own waiting moves first: points placed at their
    // corrected place must not then move by the debt of what was there before.
    finishMovesWithin(kept);
    const bool moves_pending = std::any_of(planes.begin(), planes.end(),
                                           [this](int id) { return moving_planes_.count(id) > 0; });
    for (std::size_t m = planes.size(); m-- > 1 && !moves_pending;) {
      mergePlane(kept, planes[m], ids);
    }
    ids.push_back(placePoints(kept, observation.points_W, moments, observation.keyframe_ns));
    if (observation.keyframe_ns) {
      Plane::Observer& observer = planes_.at(kept).observers[*observation.keyframe_ns];
      observer.points += static_cast<double>(observation.points_W.size());
      observer.motion = observation.loop_motion;
    }
  }
  return ids;
}

std::vector<int> finalizedIds(const std::vector<PatchEvent>& events) {
  std::vector<int> ids;
  for (const PatchEvent& event : events) {
    if (event.kind == PatchEvent::Kind::kFinalized) ids.push_back(event.id);
  }
  return ids;
}

PatchSnapshot PatchMap::snapshot(const Patch& patch) const {
  PatchSnapshot snapshot;
  snapshot.id = patch.id;
  snapshot.version = patch.version;
  snapshot.normal = patch.normal();
  snapshot.offset = patch.offset();
  snapshot.frame = patch.planeFrame();
  snapshot.outline = outlineOf(patch);
  snapshot.shared_samples = patch.samples.share();
  if (patch.footprint_pixels > 0 && !patch.log_gain_sum.isZero()) {
    // Samples were compensated to the first frame's exposure; the mean exposure of the frames
    // that coloured the patch fits its views best.
    snapshot.colour_scale =
        (-patch.log_gain_sum / static_cast<double>(patch.footprint_pixels)).array().exp();
  }
  if (patch.footprint_pixels > 0) {
    snapshot.pixel_footprint_m =
        patch.footprint_sum_m / static_cast<double>(patch.footprint_pixels);
  }
  return snapshot;
}

std::vector<ColourSample> sampleList(const PatchSnapshot& patch) {
  if (!patch.shared_samples) return patch.samples;
  std::vector<ColourSample> samples = patch.shared_samples->all();
  if (patch.colour_scale) {
    const Eigen::Vector3d& scale = *patch.colour_scale;
    for (ColourSample& sample : samples) {
      for (int c = 0; c < 3; ++c) {
        const auto i = static_cast<std::size_t>(c);
        sample.rgb[i] = cv::saturate_cast<std::uint8_t>(scale[c] * sample.rgb[i]);
      }
    }
  }
  return samples;
}

std::size_t sampleCount(const PatchSnapshot& patch) {
  return patch.shared_samples ? patch.shared_samples->size() : patch.samples.size();
}

const Patch* PatchMap::find(int id) const {
  const auto it = patches_.find(id);
  return it == patches_.end() ? nullptr : &it->second;
}

std::size_t PatchMap::liveCount() const {
  std::size_t live = 0;
  for (const auto& [id, patch] : patches_) live += patch.finalized ? 0 : 1;
  return live;
}

std::size_t PatchMap::finalizedCount() const { return patches_.size() - liveCount(); }

}  // namespace tessera::planes
