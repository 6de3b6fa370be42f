#pragma once
// A plane of the patch map (patch_map.h): where it lies, every point it was given (for the
// least-squares refit), how it is cut into tiles and which keyframes saw it. Its tiles (Patch)
// hold the cells and colours; they read the plane's geometry and never keep a copy of it.
#include <array>
#include <cstddef>
#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <vector>

#include <Eigen/Core>

#include "tessera/core/pose.h"
#include "tessera/planes/patch_outline.h"
#include "tessera/planes/plane_fit.h"

namespace tessera::planes {

// Where a plane lies: n . X = offset, with an in-plane frame fixed when the plane is created
// (cells are indexed in (u, v) from origin).
struct PlaneGeometry {
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();
  double offset = 0.0;
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();
  Eigen::Vector3d u_axis = Eigen::Vector3d::UnitX();
  Eigen::Vector3d v_axis = Eigen::Vector3d::UnitY();

  // The in-plane frame made exact for the refitted plane: origin moved onto it along the
  // normal, axes made orthogonal to the normal. Cells and samples keep their (u, v).
  struct Frame {
    Eigen::Vector3d origin, u_axis, v_axis;
    Eigen::Vector3d at(double u, double v) const { return origin + u * u_axis + v * v_axis; }
  };
  Frame planeFrame() const;

  Cell cellOf(const Eigen::Vector3d& X_W, double cell_m) const;
  Eigen::Vector3d cellCentre(const Cell& cell, double cell_m) const;
  // The plane carried by a rigid motion, its frame with it.
  void move(const core::Isometry& motion);
};

// How a plane is cut into tiles: per axis (u, v), the cell index where tile 0 starts, set
// once the plane outgrew one tile; before that one tile holds the whole plane on that axis.
struct TileGrid {
  int tile_cells = 0;  // tile side in cells; 0: never cut
  std::array<std::optional<int>, 2> anchor;
  Cell keyOf(const Cell& cell) const;
  bool cut() const { return anchor[0].has_value() || anchor[1].has_value(); }
};

struct Plane {
  int id = 0;
  // Shared with its tiles, which only read it.
  std::shared_ptr<PlaneGeometry> geometry = std::make_shared<PlaneGeometry>();
  PointMoments moments;  // of every point ever added, for the least-squares refit
  TileGrid grid;
  Cell lo{0, 0}, hi{0, 0};  // bounds of every cell of every tile (once has_cells)
  bool has_cells = false;
  std::map<Cell, int> tiles;  // tile key in `grid` -> the tile's patch id
  // By keyframe time: the points its frames gave, and the loop-closure motion they were
  // placed with.
  struct Observer {
    double points = 0.0;
    core::Isometry motion = core::Isometry::Identity();
  };
  std::map<std::int64_t, Observer> observers;
  // Where on the plane each keyframe's points fell: per block of kBlockCells x kBlockCells
  // cells, the keyframes that gave it most points (at most kSourcesPerBlock). A correction
  // moves each block within the plane by its own keyframes' moves, where the plane as a whole
  // moves by their mean (PatchMap::followCorrection): a floor fused along a drifting path is
  // bent back in its plane, not only turned and shifted.
  static constexpr int kBlockCells = 2;
  static constexpr std::size_t kSourcesPerBlock = 8;
  struct Source {
    std::int64_t keyframe_ns = 0;
    float points = 0.0F;
  };
  struct Block {
    std::vector<Source> sources;
    // The in-plane move (u, v metres) corrections asked of the block and not yet made: its
    // tile moves once some block of it is owed enough to show.
    Eigen::Vector2f owed = Eigen::Vector2f::Zero();
    // Cells move by whole cells, colour samples by the exact amount: the part of the moves made
    // that the block's cells have not made yet (each axis within half a cell).
    Eigen::Vector2f cell_lag = Eigen::Vector2f::Zero();
  };
  std::map<Cell, Block> blocks;  // by block (cell / kBlockCells, floored)
  static Cell blockOf(const Cell& cell);
  // Counts `points` points from `keyframe_ns` in `block`; the block keeps the keyframes that
  // gave it most.
  void addSource(const Cell& block, std::int64_t keyframe_ns, float points);

  // Fits the plane to every point it got, keeping the side its normal points to.
  void refit();
  // Carries the plane (its geometry and its points' moments) by a rigid motion.
  void move(const core::Isometry& motion);
  // Grows the bounds by `cells`, cutting the grid along an axis the plane outgrows.
  void extendGrid(const std::vector<Cell>& cells);
};

}  // namespace tessera::planes
