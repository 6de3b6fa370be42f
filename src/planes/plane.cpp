#include "tessera/planes/plane.h"

#include <algorithm>
#include <cmath>

namespace tessera::planes {

namespace {

int& axis(Cell& cell, int a) { return a == 0 ? cell.first : cell.second; }
int axis(const Cell& cell, int a) { return a == 0 ? cell.first : cell.second; }

int floorDiv(int a, int b) { return a >= 0 ? a / b : -((-a + b - 1) / b); }

// The moments of the points moved by `motion`: for X' = R X + t,
// sum' = R sum + n t and outer' = R outer R^T + R sum t^T + t (R sum)^T + n t t^T.
PointMoments moved(const PointMoments& m, const core::Isometry& motion) {
  const Eigen::Matrix3d R = motion.linear();
  const Eigen::Vector3d t = motion.translation();
  const Eigen::Vector3d rotated_sum = R * m.sum;
  PointMoments out;
  out.count = m.count;
  out.sum = rotated_sum + m.count * t;
  out.outer = R * m.outer * R.transpose() + rotated_sum * t.transpose() +
              t * rotated_sum.transpose() + m.count * t * t.transpose();
  return out;
}

}  // namespace

PlaneGeometry::Frame PlaneGeometry::planeFrame() const {
  Frame frame;
  frame.origin = origin + (offset - normal.dot(origin)) * normal;
  frame.u_axis = (u_axis - u_axis.dot(normal) * normal).normalized();
  frame.v_axis = normal.cross(frame.u_axis);
  return frame;
}

Cell PlaneGeometry::cellOf(const Eigen::Vector3d& X_W, double cell_m) const {
  const Eigen::Vector3d d = X_W - origin;
  return {static_cast<int>(std::floor(d.dot(u_axis) / cell_m)),
          static_cast<int>(std::floor(d.dot(v_axis) / cell_m))};
}

Eigen::Vector3d PlaneGeometry::cellCentre(const Cell& cell, double cell_m) const {
  return origin + (cell.first + 0.5) * cell_m * u_axis + (cell.second + 0.5) * cell_m * v_axis;
}

void PlaneGeometry::move(const core::Isometry& motion) {
  const Eigen::Matrix3d R = motion.linear();
  origin = motion * origin;
  u_axis = R * u_axis;
  v_axis = R * v_axis;
  normal = R * normal;
  // A point X of the plane (n . X = offset) moves to R X + t: n' . X' = offset + n' . t.
  offset += normal.dot(motion.translation());
}

Cell TileGrid::keyOf(const Cell& cell) const {
  Cell key{0, 0};
  for (int a = 0; a < 2; ++a) {
    if (anchor[a]) axis(key, a) = floorDiv(axis(cell, a) - *anchor[a], tile_cells);
  }
  return key;
}

Cell Plane::blockOf(const Cell& cell) {
  return {floorDiv(cell.first, kBlockCells), floorDiv(cell.second, kBlockCells)};
}

void Plane::addSource(const Cell& block, std::int64_t keyframe_ns, float points) {
  std::vector<Source>& block_sources = blocks[block].sources;
  const auto same = std::find_if(block_sources.begin(), block_sources.end(),
                                 [&](const Source& s) { return s.keyframe_ns == keyframe_ns; });
  if (same != block_sources.end()) {
    same->points += points;
    return;
  }
  if (block_sources.size() < kSourcesPerBlock) {
    block_sources.push_back({keyframe_ns, points});
    return;
  }
  // Full: the new keyframe takes the place of the one that gave least, if it gave more.
  const auto least =
      std::min_element(block_sources.begin(), block_sources.end(),
                       [](const Source& a, const Source& b) { return a.points < b.points; });
  if (least->points < points) *least = {keyframe_ns, points};
}

void Plane::refit() {
  const PlaneFit fit = fitPlane(moments);
  // Keep the orientation the plane was created with.
  const double sign = fit.normal.dot(geometry->normal) < 0.0 ? -1.0 : 1.0;
  geometry->normal = sign * fit.normal;
  geometry->offset = sign * fit.offset;
}

void Plane::move(const core::Isometry& motion) {
  moments = moved(moments, motion);
  geometry->move(motion);
}

void Plane::extendGrid(const std::vector<Cell>& cells) {
  if (cells.empty()) return;
  Cell cells_lo = cells.front(), cells_hi = cells.front();
  for (const Cell& c : cells) {
    for (int a = 0; a < 2; ++a) {
      axis(cells_lo, a) = std::min(axis(cells_lo, a), axis(c, a));
      axis(cells_hi, a) = std::max(axis(cells_hi, a), axis(c, a));
    }
  }
  const int size = grid.tile_cells;
  for (int a = 0; a < 2; ++a) {
    const int old_lo = axis(lo, a), old_hi = axis(hi, a);
    const int new_lo = has_cells ? std::min(old_lo, axis(cells_lo, a)) : axis(cells_lo, a);
    const int new_hi = has_cells ? std::max(old_hi, axis(cells_hi, a)) : axis(cells_hi, a);
    if (size > 0 && !grid.anchor[a] && new_hi - new_lo + 1 > size) {
      // The tile that held the whole plane so far stays tile 0: it spans at most one tile.
      if (!has_cells || new_hi >= old_lo + size) {
        grid.anchor[a] = has_cells ? old_lo : new_lo;
      } else {
        grid.anchor[a] = old_hi + 1 - size;
      }
    }
    axis(lo, a) = new_lo;
    axis(hi, a) = new_hi;
  }
  has_cells = true;
}

}  // namespace tessera::planes
