#include "internal/lattice_refinement.h"

#include <array>
#include <cmath>
#include <cstdint>
#include <limits>

#include <opencv2/imgproc.hpp>

namespace tessera::pattern {

namespace {

// Mean squared colour difference between texels x and x + d over valid pairs on a sparse
// grid (every `stride` texels); infinity when too few pairs.
double repeatCost(const cv::Mat& rgb, const cv::Mat& mask, const Eigen::Vector2d& d, int stride) {
  const int dx0 = static_cast<int>(std::floor(d.x())), dy0 = static_cast<int>(std::floor(d.y()));
  const float fx = static_cast<float>(d.x() - dx0), fy = static_cast<float>(d.y() - dy0);
  double sum = 0.0;
  std::size_t pairs = 0;
  for (int row = 0; row < rgb.rows; row += stride) {
    const int y = row + dy0;
    if (y < 0 || y + 1 >= rgb.rows) continue;
    const auto* here = rgb.ptr<cv::Vec3f>(row);
    const auto* top = rgb.ptr<cv::Vec3f>(y);
    const auto* bottom = rgb.ptr<cv::Vec3f>(y + 1);
    const std::uint8_t* valid = mask.empty() ? nullptr : mask.ptr<std::uint8_t>(row);
    const std::uint8_t* valid_top = mask.empty() ? nullptr : mask.ptr<std::uint8_t>(y);
    const std::uint8_t* valid_bottom = mask.empty() ? nullptr : mask.ptr<std::uint8_t>(y + 1);
    for (int col = 0; col < rgb.cols; col += stride) {
      const int x = col + dx0;
      if (x < 0 || x + 1 >= rgb.cols) continue;
      if (valid != nullptr && (valid[col] == 0 || valid_top[x] == 0 || valid_top[x + 1] == 0 ||
                               valid_bottom[x] == 0 || valid_bottom[x + 1] == 0)) {
        continue;
      }
      const cv::Vec3f shifted = (1 - fy) * ((1 - fx) * top[x] + fx * top[x + 1]) +
                                fy * ((1 - fx) * bottom[x] + fx * bottom[x + 1]);
      const cv::Vec3f e = shifted - here[col];
      sum += e.dot(e);
      ++pairs;
    }
  }
  return pairs >= 64 ? sum / static_cast<double>(pairs) : std::numeric_limits<double>::infinity();
}

// Compass search for the least repeat cost near `start`, steps 1 down to 1/8 texel.
Eigen::Vector2d bestShiftNear(const cv::Mat& rgb, const cv::Mat& mask, Eigen::Vector2d start,
                              int stride) {
  double best = repeatCost(rgb, mask, start, stride);
  const std::array<Eigen::Vector2d, 4> moves{Eigen::Vector2d(1, 0), Eigen::Vector2d(-1, 0),
                                             Eigen::Vector2d(0, 1), Eigen::Vector2d(0, -1)};
  for (double step = 1.0; step >= 0.125; step /= 2.0) {
    for (int iteration = 0; iteration < 8; ++iteration) {
      Eigen::Vector2d next = start;
      for (const Eigen::Vector2d& m : moves) {
        const double c = repeatCost(rgb, mask, start + step * m, stride);
        if (c < best) best = c, next = start + step * m;
      }
      if (next == start) break;
      start = next;
    }
  }
  return start;
}

}  // namespace

core::Lattice2 refineLattice(const cv::Mat& rgb, const cv::Mat& mask, core::Lattice2 lattice,
                             int vectors) {
  cv::Mat smooth;
  rgb.convertTo(smooth, CV_32FC3);
  cv::GaussianBlur(smooth, smooth, cv::Size(), 1.0);
  // About 20,000 pairs per cost, whatever the bitmap's size.
  const int stride =
      std::max(1, static_cast<int>(std::sqrt(static_cast<double>(rgb.total()) / 2e4)));
  for (int i = 0; i < vectors; ++i) {
    Eigen::Vector2d& v = i == 0 ? lattice.v1 : lattice.v2;
    for (int k = 2; k <= 8; k *= 2) {
      const Eigen::Vector2d far = k * v;
      if (std::abs(far.x()) > rgb.cols / 2.0 || std::abs(far.y()) > rgb.rows / 2.0) break;
      v = bestShiftNear(smooth, mask, far, stride) / k;
    }
  }
  return lattice;
}

}  // namespace tessera::pattern
