#pragma once
// A 2D lattice {n v1 + m v2 : n, m integers}: the translations under which a periodic texture
// is unchanged. A pattern texture stores one cell of it as a W x H tile: tile pixel (i, j)
// shows the point (i / W) v1 + (j / H) v2 of the texture frame, so the tile repeats exactly
// along both of its axes whatever the lattice's shear or rotation.
#include <cmath>

#include <Eigen/Core>
#include <Eigen/LU>

namespace tessera::core {

struct Lattice2 {
  Eigen::Vector2d v1 = Eigen::Vector2d::Zero();
  Eigen::Vector2d v2 = Eigen::Vector2d::Zero();

  Eigen::Matrix2d basis() const {
    Eigen::Matrix2d m;
    m << v1, v2;
    return m;
  }
  // Area of one cell (0 for a degenerate basis).
  double cellArea() const { return std::abs(v1.x() * v2.y() - v1.y() * v2.x()); }
  // Lattice coordinates (c1, c2) of a point: p = c1 v1 + c2 v2.
  Eigen::Vector2d coordinatesOf(const Eigen::Vector2d& p) const { return basis().inverse() * p; }
};

}  // namespace tessera::core
