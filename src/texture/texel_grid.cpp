#include "tessera/texture/texel_grid.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include <Eigen/Eigenvalues>
#include <opencv2/imgproc.hpp>

namespace tessera::texture {

namespace {

std::vector<Eigen::Vector2d> verticesOf(const planes::Outline& outline) {
  std::vector<Eigen::Vector2d> vertices;
  for (const planes::OutlinePart& part : outline.parts) {
    vertices.insert(vertices.end(), part.outer.begin(), part.outer.end());
    for (const planes::Polygon2& hole : part.holes) {
      vertices.insert(vertices.end(), hole.begin(), hole.end());
    }
  }
  return vertices;
}

// The grid with the given axes spanning the vertices' bounding box in that frame.
TexelGrid gridAlong(const std::vector<Eigen::Vector2d>& vertices, const Eigen::Vector2d& x_axis,
                    double texel_m) {
  TexelGrid grid;
  grid.texel_m = texel_m;
  grid.x_axis = x_axis.normalized();
  grid.y_axis = Eigen::Vector2d(-grid.x_axis.y(), grid.x_axis.x());
  if (vertices.empty()) return grid;
  double lo_x = std::numeric_limits<double>::max(), hi_x = -lo_x, lo_y = lo_x, hi_y = -lo_x;
  for (const Eigen::Vector2d& p : vertices) {
    lo_x = std::min(lo_x, p.dot(grid.x_axis)), hi_x = std::max(hi_x, p.dot(grid.x_axis));
    lo_y = std::min(lo_y, p.dot(grid.y_axis)), hi_y = std::max(hi_y, p.dot(grid.y_axis));
  }
  grid.origin_uv = lo_x * grid.x_axis + lo_y * grid.y_axis;
  grid.width = std::max(1, static_cast<int>(std::ceil((hi_x - lo_x) / texel_m)));
  grid.height = std::max(1, static_cast<int>(std::ceil((hi_y - lo_y) / texel_m)));
  return grid;
}

// Polygon vertices in grid pixel coordinates, in fixed point with kShift fractional bits.
constexpr int kShift = 4;
std::vector<cv::Point> toGridPixels(const planes::Polygon2& polygon, const TexelGrid& grid) {
  std::vector<cv::Point> points;
  for (const Eigen::Vector2d& p : polygon) {
    const Eigen::Vector2d d = p - grid.origin_uv;
    // fillPoly fills pixels whose centres are inside; pixel (c, r) has its centre at texel
    // coordinates (c + 0.5, r + 0.5), so shift by half a texel.
    const double col = d.dot(grid.x_axis) / grid.texel_m - 0.5;
    const double row = d.dot(grid.y_axis) / grid.texel_m - 0.5;
    points.emplace_back(static_cast<int>(std::lround(col * (1 << kShift))),
                        static_cast<int>(std::lround(row * (1 << kShift))));
  }
  return points;
}

void fillMask(const planes::Outline& outline, TexelGrid& grid) {
  grid.mask = cv::Mat::zeros(grid.height, grid.width, CV_8UC1);
  for (const planes::OutlinePart& part : outline.parts) {
    std::vector<std::vector<cv::Point>> rings{toGridPixels(part.outer, grid)};
    for (const planes::Polygon2& hole : part.holes) rings.push_back(toGridPixels(hole, grid));
    // Even-odd filling leaves the holes out.
    cv::fillPoly(grid.mask, rings, cv::Scalar(255), cv::LINE_8, kShift);
  }
}

Eigen::Vector2d principalAxis(const std::vector<Eigen::Vector2d>& vertices) {
  if (vertices.size() < 2) return Eigen::Vector2d::UnitX();
  Eigen::Vector2d mean = Eigen::Vector2d::Zero();
  for (const auto& p : vertices) mean += p;
  mean /= static_cast<double>(vertices.size());
  Eigen::Matrix2d scatter = Eigen::Matrix2d::Zero();
  for (const auto& p : vertices) scatter += (p - mean) * (p - mean).transpose();
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> solver(scatter);
  return solver.eigenvectors().col(1);  // eigenvalues ascend: the largest spread
}

// The direction of the minimum-area rectangle's first side, or +u with fewer than 3 vertices.
Eigen::Vector2d minimumAreaAxis(const std::vector<Eigen::Vector2d>& vertices) {
  std::vector<cv::Point2f> points;
  for (const auto& p : vertices) {
    points.emplace_back(static_cast<float>(p.x()), static_cast<float>(p.y()));
  }
  if (points.size() < 3) return Eigen::Vector2d::UnitX();
  const double angle = cv::minAreaRect(points).angle * M_PI / 180.0;
  return {std::cos(angle), std::sin(angle)};
}

}  // namespace

TexelGrid minimumAreaGrid(const planes::Outline& outline, double texel_m) {
  const std::vector<Eigen::Vector2d> vertices = verticesOf(outline);
  TexelGrid grid = gridAlong(vertices, minimumAreaAxis(vertices), texel_m);
  fillMask(outline, grid);
  return grid;
}

TexelGrid principalAxisGrid(const planes::Outline& outline, double texel_m) {
  const std::vector<Eigen::Vector2d> vertices = verticesOf(outline);
  TexelGrid grid = gridAlong(vertices, principalAxis(vertices), texel_m);
  fillMask(outline, grid);
  return grid;
}

GridSizes compareGrids(const planes::Outline& outline, double texel_m) {
  const std::vector<Eigen::Vector2d> vertices = verticesOf(outline);
  GridSizes sizes;
  sizes.principal_axes = gridAlong(vertices, principalAxis(vertices), texel_m).texels();
  sizes.axis_aligned = gridAlong(vertices, Eigen::Vector2d::UnitX(), texel_m).texels();
  sizes.minimum_area = gridAlong(vertices, minimumAreaAxis(vertices), texel_m).texels();
  return sizes;
}

double pixelFootprintTexel(double viewing_distance_m, double fx) {
  return viewing_distance_m / fx;
}

}  // namespace tessera::texture
