#pragma once
// A patch's outline in its plane: the occupancy grid of the cells its points fell in, closed
// over one-cell gaps, traced into outer polygons with their holes and simplified.
#include <set>
#include <utility>
#include <vector>

#include <Eigen/Core>

namespace tessera::planes {

using Cell = std::pair<int, int>;
using Polygon2 = std::vector<Eigen::Vector2d>;  // (u, v) metres, no repeated closing vertex

struct OutlinePart {
  Polygon2 outer;
  std::vector<Polygon2> holes;
};

struct Outline {
  std::vector<OutlinePart> parts;
  double area_m2 = 0.0;  // of the closed occupancy grid
};

// Cell (i, j) covers [i, i+1) x [j, j+1) times cell_m. Vertices are simplified to within half
// a cell of the grid's boundary.
Outline traceOutline(const std::set<Cell>& cells, double cell_m);

// Area of a simple polygon (shoelace formula), positive whatever its orientation.
double polygonArea(const Polygon2& polygon);

}  // namespace tessera::planes
