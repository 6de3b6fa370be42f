#pragma once
// A patch's outline in its plane: the occupancy grid of the cells its points fell in, closed
// over one-cell gaps, traced into outer polygons with their holes and simplified.
#include <cstddef>
#include <functional>
#include <unordered_set>
#include <utility>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core/mat.hpp>

namespace tessera::planes {

using Cell = std::pair<int, int>;
struct CellHash {
  std::size_t operator()(const Cell& c) const {
    return std::hash<long long>()((static_cast<long long>(c.first) << 32) ^
                                  static_cast<unsigned int>(c.second));
  }
};
using CellSet = std::unordered_set<Cell, CellHash>;
using Polygon2 = std::vector<Eigen::Vector2d>;  // (u, v) metres, no repeated closing vertex

struct OutlinePart {
  Polygon2 outer;
  std::vector<Polygon2> holes;
};

struct Outline {
  std::vector<OutlinePart> parts;
  double area_m2 = 0.0;  // of the closed occupancy grid
  // The closed occupancy grid: CV_8U, 255 where occupied; grid(r, c) is cell
  // (first_cell.first + c, first_cell.second + r).
  cv::Mat grid;
  Cell first_cell{0, 0};
};

// Cell (i, j) covers [i, i+1) x [j, j+1) times cell_m. Vertices are simplified to within half
// a cell of the grid's boundary.
Outline traceOutline(const CellSet& cells, double cell_m);

// Area of a simple polygon (shoelace formula), positive whatever its orientation.
double polygonArea(const Polygon2& polygon);

}  // namespace tessera::planes
