// PatchMap after a loop closure: planes move with the keyframes they were seen from, their
// blocks within them by their own keyframes, and a place mapped twice (once before the drift,
// once after) becomes one plane again.
#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <optional>
#include <set>
#include <utility>
#include <vector>

#include <Eigen/Geometry>

#include "tessera/planes/patch_map.h"

namespace tessera::planes {

namespace {

// A move below these is left alone: it changes no cell, and moving would cost re-association.
constexpr double kMinMove_m = 0.002;
constexpr double kMinTurn_deg = 0.05;

// The centre, in the plane's (u, v), of the square `key` of a grid of `side_m` squares.
Eigen::Vector2d squareCentre(const Cell& key, double side_m) {
  return {(key.first + 0.5) * side_m, (key.second + 0.5) * side_m};
}

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
    std::map<std::int64_t, core::Isometry> steps;
    for (auto& [keyframe_ns, observer] : plane.observers) {
      const core::Isometry target = motion_at(keyframe_ns);
      const core::Isometry step = target * observer.motion.inverse();
      steps.emplace(keyframe_ns, step);
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
    if (oweWithinPlane(plane, motion, steps)) moving_planes_.insert(plane_id);
    ++moved_planes;
  }
  moveWithinPlanes();
  return moved_planes;
}

std::size_t PatchMap::moveWithinPlanes() {
  const auto most = static_cast<std::size_t>(std::max(0, config_.max_tiles_moved_per_frame));
  std::size_t moved = 0;
  while (!moving_planes_.empty() && (most == 0 || moved < most)) {
    moved += finishMovesWithin(*moving_planes_.begin());
  }
  return moved;
}

std::size_t PatchMap::finishMovesWithin(int plane_id) {
  if (moving_planes_.erase(plane_id) == 0) return 0;
  const auto plane = planes_.find(plane_id);
  return plane != planes_.end() ? moveDueTiles(plane->second) : 0;
}

bool PatchMap::oweWithinPlane(Plane& plane, const core::Isometry& plane_motion,
                              const std::map<std::int64_t, core::Isometry>& steps) {
  if (!config_.move_within_plane || plane.blocks.empty()) return false;
  // The plane's frame has moved with it; a block at (u, v) was at `back * moved` before.
  const PlaneGeometry& now = *plane.geometry;
  const core::Isometry back = plane_motion.inverse();
  const double block_m = Plane::kBlockCells * config_.cell_m;
  // Each block is owed, besides what earlier corrections left, where its keyframes' moves take
  // its centre (their mean, weighted by points) less where the plane's move took it, within
  // the plane.
  bool due = false;
  for (auto& [key, block] : plane.blocks) {
    const Eigen::Vector2d uv = squareCentre(key, block_m);
    const Eigen::Vector3d moved = now.origin + uv.x() * now.u_axis + uv.y() * now.v_axis;
    const Eigen::Vector3d was = back * moved;
    Eigen::Vector3d target = Eigen::Vector3d::Zero();
    double points = 0.0;
    for (const Plane::Source& source : block.sources) {
      const auto step = steps.find(source.keyframe_ns);
      if (step == steps.end()) continue;
      target += source.points * (step->second * was);
      points += source.points;
    }
    if (points <= 0.0) continue;
    const Eigen::Vector3d residual = target / points - moved;
    block.owed += Eigen::Vector2d(residual.dot(now.u_axis), residual.dot(now.v_axis)).cast<float>();
    due = due || block.owed.norm() >= config_.min_move_within_plane_m;
  }
  return due;
}

std::size_t PatchMap::moveDueTiles(Plane& plane) {
  const double cell_m = config_.cell_m, block_m = Plane::kBlockCells * cell_m;
  const auto cellAt = [&](const Eigen::Vector2d& uv) {
    return Cell{static_cast<int>(std::floor(uv.x() / cell_m)),
                static_cast<int>(std::floor(uv.y() / cell_m))};
  };
  // A block may straddle two tiles (a tile's edge need not fall on the block grid): it is due
  // in the tiles of each of its cells.
  const auto tilesOfBlock = [&](const Cell& key) {
    std::set<Cell> keys;
    for (int du = 0; du < Plane::kBlockCells; ++du) {
      for (int dv = 0; dv < Plane::kBlockCells; ++dv) {
        keys.insert(plane.grid.keyOf(
            {key.first * Plane::kBlockCells + du, key.second * Plane::kBlockCells + dv}));
      }
    }
    return keys;
  };
  std::set<Cell> due_tiles;  // tiles with a block owed enough to show
  for (const auto& [key, block] : plane.blocks) {
    if (block.owed.norm() >= config_.min_move_within_plane_m) {
      const std::set<Cell> keys = tilesOfBlock(key);
      due_tiles.insert(keys.begin(), keys.end());
    }
  }
  if (due_tiles.empty()) return 0;
  // In a due tile every block moves by what it is owed (its samples exactly, its cells by whole
  // cells, the rest kept as its lag); the others wait for a later correction.
  struct Shift {
    Eigen::Vector2d samples = Eigen::Vector2d::Zero();
    Eigen::Vector2i cells = Eigen::Vector2i::Zero();
  };
  std::map<Cell, Shift> shifts;
  for (const auto& [key, block] : plane.blocks) {
    const std::set<Cell> keys = tilesOfBlock(key);
    if (std::none_of(keys.begin(), keys.end(),
                     [&](const Cell& tile) { return due_tiles.count(tile) > 0; })) {
      continue;
    }
    Shift shift;
    shift.samples = block.owed.cast<double>();
    const Eigen::Vector2d total = (block.owed + block.cell_lag).cast<double>() / cell_m;
    shift.cells = Eigen::Vector2i(static_cast<int>(std::lround(total.x())),
                                  static_cast<int>(std::lround(total.y())));
    shifts.emplace(key, shift);
  }
  // Samples come tile by tile: most look up the block the one before them did.
  Cell last_block{std::numeric_limits<int>::min(), 0};
  Shift last_shift;
  const auto shiftAt = [&](const Eigen::Vector2d& uv) -> const Shift& {
    const Cell block = Plane::blockOf(cellAt(uv));
    if (block != last_block) {
      const auto it = shifts.find(block);
      last_block = block;
      last_shift = it == shifts.end() ? Shift{} : it->second;
    }
    return last_shift;
  };

  // Take the cells out of the due tiles, then put them back at their shifted places, in
  // whichever tile now holds each. A tile the move creates takes the footprint and exposure
  // figures of the tile its first cell came from.
  std::vector<std::pair<Cell, Patch*>> cells;  // where each goes, and the tile it came from
  std::vector<Patch*> due;
  std::set<int> changed;
  for (const Cell& key : due_tiles) {
    const auto id = plane.tiles.find(key);
    if (id == plane.tiles.end()) continue;
    Patch& tile = patchWithId(id->second);
    restoreSamples(tile);
    for (const Cell& c : tile.cells) {
      const Eigen::Vector2i by = shiftAt(squareCentre(c, cell_m)).cells;
      cells.push_back({{c.first + by.x(), c.second + by.y()}, &tile});
    }
    tile.cells.clear();
    due.push_back(&tile);
    changed.insert(tile.id);
  }
  {
    std::vector<Cell> to;
    to.reserve(cells.size());
    for (const auto& entry : cells) to.push_back(entry.first);
    plane.extendGrid(to);
  }
  for (const auto& [c, from] : cells) {
    Patch& tile = tileAt(plane.id, plane.grid.keyOf(c));
    if (tile.footprint_pixels == 0 && tile.cells.empty()) {
      tile.footprint_sum_m = from->footprint_sum_m;
      tile.footprint_pixels = from->footprint_pixels;
      tile.log_gain_sum = from->log_gain_sum;
    }
    restoreSamples(tile);
    tile.cells.insert(c);
    changed.insert(tile.id);
  }
  // The samples, one due tile at a time (its old samples are let go before the next): into the
  // due tiles' new samples, or added to another tile's.
  std::map<int, ColourSamples> rebuilt;
  for (const Patch* tile : due) {
    rebuilt.emplace(tile->id, ColourSamples(config_.sample_cell_m, config_.sample_views));
  }
  std::set<Patch*> sampled;
  Cell last_key{std::numeric_limits<int>::min(), 0};
  ColourSamples* into = nullptr;
  for (Patch* tile : due) {
    const std::vector<ColourSample> samples = tile->samples->all();
    tile->samples = ColourSamples(config_.sample_cell_m, config_.sample_views);
    for (ColourSample sample : samples) {
      const Eigen::Vector2d& shift = shiftAt(Eigen::Vector2d(sample.u, sample.v)).samples;
      sample.u += static_cast<float>(shift.x());
      sample.v += static_cast<float>(shift.y());
      const Cell key = plane.grid.keyOf(cellAt(Eigen::Vector2d(sample.u, sample.v)));
      if (key != last_key) {
        last_key = key;
        into = nullptr;
        if (const auto id = plane.tiles.find(key); id != plane.tiles.end()) {
          if (const auto fresh = rebuilt.find(id->second); fresh != rebuilt.end()) {
            into = &fresh->second;
          } else {
            Patch& other = patchWithId(id->second);
            restoreSamples(other);
            into = &other.samples.edit();
            sampled.insert(&other);
            changed.insert(other.id);  // its content changed: a new version
          }
        }
      }
      if (into != nullptr) into->add(sample);  // none: moved off every tile
    }
  }
  for (auto& [id, samples] : rebuilt) {
    samples.settle();
    patchWithId(id).samples = std::move(samples);
  }
  for (Patch* tile : sampled) tile->samples.edit().settle();
  // The blocks of the due tiles move too, their debt paid (but for their cells' lag).
  std::map<Cell, Plane::Block> was_blocks;
  was_blocks.swap(plane.blocks);
  for (auto& [key, block] : was_blocks) {
    const auto shift = shifts.find(key);
    if (shift == shifts.end()) {  // its tiles were not due
      Plane::Block& kept = plane.blocks[key];
      kept.owed += block.owed;
      kept.cell_lag = block.cell_lag;
      for (const Plane::Source& source : block.sources) {
        plane.addSource(key, source.keyframe_ns, source.points);
      }
      continue;
    }
    const Eigen::Vector2d centre = squareCentre(key, block_m);
    const Cell to = Plane::blockOf(cellAt(centre + shift->second.samples));
    for (const Plane::Source& source : block.sources) {
      plane.addSource(to, source.keyframe_ns, source.points);
    }
    plane.blocks[to].cell_lag = block.owed + block.cell_lag -
                                shift->second.cells.cast<float>() * static_cast<float>(cell_m);
  }
  tiles_moved_within_planes_ += due.size();
  for (const int id : changed) {
    Patch& tile = patchWithId(id);
    if (!tile.cells.empty()) {
      // A new version from the moved cells and samples, once the burst of corrections is over.
      tile.finalized = false;
      tile.frames_to_settle = config_.moved_settle_frames;
      continue;
    }
    // Everything it held moved into a neighbouring tile.
    if (tile.version > 0) pending_.push_back({PatchEvent::Kind::kRetired, id, tile.version});
    seen_this_frame_.erase(id);
    plane.tiles.erase(tile.tile);
    patches_.erase(id);
  }
  return due.size();
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
