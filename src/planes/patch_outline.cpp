#include "tessera/planes/patch_outline.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <opencv2/imgproc.hpp>

namespace tessera::planes {

namespace {

// The grid is traced at kUpsample pixels per cell, so that contour pixels (whose centres are
// the traced vertices) lie 1/8 of a cell inside the true boundary rather than half a cell.
constexpr int kUpsample = 4;
constexpr int kBorder = 1;  // empty cells around the occupied ones

Polygon2 toPlane(const std::vector<cv::Point>& contour, int min_i, int min_j, double cell_m) {
  std::vector<cv::Point> simplified;
  cv::approxPolyDP(contour, simplified, kUpsample / 2.0, true);
  Polygon2 polygon;
  for (const cv::Point& p : simplified) {
    // Grid column g holds cell min_i - kBorder + g, and pixel x lies in g = x / kUpsample.
    polygon.emplace_back(((p.x + 0.5) / kUpsample + min_i - kBorder) * cell_m,
                         ((p.y + 0.5) / kUpsample + min_j - kBorder) * cell_m);
  }
  return polygon;
}

}  // namespace

double polygonArea(const Polygon2& polygon) {
  double twice = 0.0;
  for (std::size_t i = 0; i < polygon.size(); ++i) {
    const Eigen::Vector2d& a = polygon[i];
    const Eigen::Vector2d& b = polygon[(i + 1) % polygon.size()];
    twice += a.x() * b.y() - b.x() * a.y();
  }
  return std::abs(twice) / 2.0;
}

Outline traceOutline(const CellSet& cells, double cell_m) {
  Outline outline;
  if (cells.empty()) return outline;
  int min_i = std::numeric_limits<int>::max(), min_j = min_i;
  int max_i = std::numeric_limits<int>::min(), max_j = max_i;
  for (const auto& [i, j] : cells) {
    min_i = std::min(min_i, i), max_i = std::max(max_i, i);
    min_j = std::min(min_j, j), max_j = std::max(max_j, j);
  }
  // Empty border cells on each side, so contours never touch the image edge.
  cv::Mat grid =
      cv::Mat::zeros(max_j - min_j + 1 + 2 * kBorder, max_i - min_i + 1 + 2 * kBorder, CV_8UC1);
  for (const auto& [i, j] : cells) {
    grid.at<std::uint8_t>(j - min_j + kBorder, i - min_i + kBorder) = 255;
  }
  // Close one-cell gaps left where no point happened to fall (outside the image is empty).
  cv::morphologyEx(grid, grid, cv::MORPH_CLOSE, cv::Mat::ones(3, 3, CV_8UC1), cv::Point(-1, -1), 1,
                   cv::BORDER_CONSTANT, cv::Scalar(0));
  outline.area_m2 = cv::countNonZero(grid) * cell_m * cell_m;
  outline.grid = grid;
  outline.first_cell = {min_i - kBorder, min_j - kBorder};

  cv::Mat fine;
  cv::resize(grid, fine, cv::Size(), kUpsample, kUpsample, cv::INTER_NEAREST);
  std::vector<std::vector<cv::Point>> contours;
  std::vector<cv::Vec4i> hierarchy;  // next, previous, first child, parent
  cv::findContours(fine, contours, hierarchy, cv::RETR_CCOMP, cv::CHAIN_APPROX_SIMPLE);
  for (std::size_t c = 0; c < contours.size(); ++c) {
    if (hierarchy[c][3] >= 0) continue;  // a hole; collected with its parent
    OutlinePart part;
    part.outer = toPlane(contours[c], min_i, min_j, cell_m);
    for (int h = hierarchy[c][2]; h >= 0; h = hierarchy[static_cast<std::size_t>(h)][0]) {
      part.holes.push_back(toPlane(contours[static_cast<std::size_t>(h)], min_i, min_j, cell_m));
    }
    outline.parts.push_back(std::move(part));
  }
  return outline;
}

}  // namespace tessera::planes
