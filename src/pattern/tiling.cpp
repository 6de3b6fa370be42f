#include "internal/tiling.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "tessera/core/error.h"
#include "tessera/match/fidelity.h"
#include "tessera/pattern/pattern_extractor.h"

namespace tessera::pattern {

void averageTile(const cv::Mat& rgb, const cv::Mat& mask, const core::Lattice2& lattice, int width,
                 int height, cv::Mat& tile_rgb, cv::Mat& tile_mask, int max_repetitions) {
  tile_rgb = cv::Mat(height, width, CV_8UC3, cv::Scalar::all(0));
  tile_mask = cv::Mat(height, width, CV_8UC1, cv::Scalar(0));
  if (width <= 0 || height <= 0 || !(lattice.cellArea() > 1e-9)) return;
  // The range of cells (n, m) that reach the bitmap: its corners in lattice coordinates.
  Eigen::Vector2d low(1e18, 1e18), high(-1e18, -1e18);
  for (const Eigen::Vector2d& corner :
       {Eigen::Vector2d(0, 0), Eigen::Vector2d(rgb.cols, 0), Eigen::Vector2d(0, rgb.rows),
        Eigen::Vector2d(rgb.cols, rgb.rows)}) {
    const Eigen::Vector2d c = lattice.coordinatesOf(corner);
    low = low.cwiseMin(c);
    high = high.cwiseMax(c);
  }
  const int n0 = static_cast<int>(std::floor(low.x())) - 1,
            n1 = static_cast<int>(std::ceil(high.x()));
  const int m0 = static_cast<int>(std::floor(low.y())) - 1,
            m1 = static_cast<int>(std::ceil(high.y()));
  // Cells whose bounding box meets the bitmap, those wholly inside apart.
  const Eigen::Vector2d box_low = Eigen::Vector2d::Zero()
                                      .cwiseMin(lattice.v1)
                                      .cwiseMin(lattice.v2)
                                      .cwiseMin(lattice.v1 + lattice.v2);
  const Eigen::Vector2d box_high = Eigen::Vector2d::Zero()
                                       .cwiseMax(lattice.v1)
                                       .cwiseMax(lattice.v2)
                                       .cwiseMax(lattice.v1 + lattice.v2);
  std::vector<Eigen::Vector2d> whole, partial;
  for (int m = m0; m <= m1; ++m) {
    for (int n = n0; n <= n1; ++n) {
      const Eigen::Vector2d o = n * lattice.v1 + m * lattice.v2;
      const Eigen::Vector2d lo = o + box_low, hi = o + box_high;
      if (hi.x() < 0.0 || hi.y() < 0.0 || lo.x() > rgb.cols || lo.y() > rgb.rows) continue;
      const bool inside =
          lo.x() >= 0.0 && lo.y() >= 0.0 && hi.x() <= rgb.cols - 1 && hi.y() <= rgb.rows - 1;
      (inside ? whole : partial).push_back(o);
    }
  }
  // At most max_repetitions cells, whole ones first, each kind at even steps through its
  // row-major list (spread over the bitmap, so that an occluder keeps its share).
  const auto spread = [](const std::vector<Eigen::Vector2d>& from, std::size_t count,
                         std::vector<Eigen::Vector2d>& to) {
    count = std::min(count, from.size());
    const double step =
        count > 0 ? static_cast<double>(from.size()) / static_cast<double>(count) : 0.0;
    for (std::size_t k = 0; k < count; ++k) {
      to.push_back(from[static_cast<std::size_t>((static_cast<double>(k) + 0.5) * step)]);
    }
  };
  const std::size_t limit = max_repetitions > 0 ? static_cast<std::size_t>(max_repetitions)
                                                : whole.size() + partial.size();
  std::vector<Eigen::Vector2d> origins;
  spread(whole, limit, origins);
  spread(partial, limit - origins.size(), origins);

  // Each cell resampled onto the tile grid (tile pixel (i, j) at origin + i v1 / W + j v2 / H,
  // bilinear); a sample counts where all its taps are valid texels (the validity resampled
  // the same way stays 255 only there).
  cv::Mat base_x(height, width, CV_32FC1), base_y(height, width, CV_32FC1);
  for (int j = 0; j < height; ++j) {
    for (int i = 0; i < width; ++i) {
      const Eigen::Vector2d q = (i / static_cast<double>(width)) * lattice.v1 +
                                (j / static_cast<double>(height)) * lattice.v2;
      base_x.at<float>(j, i) = static_cast<float>(q.x());
      base_y.at<float>(j, i) = static_cast<float>(q.y());
    }
  }
  const cv::Mat validity =
      mask.empty() ? cv::Mat(rgb.size(), CV_8UC1, cv::Scalar(255)) : cv::Mat(mask != 0);
  const std::size_t texels = static_cast<std::size_t>(width) * static_cast<std::size_t>(height);
  const std::size_t cells = origins.size();
  std::vector<std::uint8_t> colours(cells * texels * 3), valid(cells * texels);
  cv::Mat map_x, map_y;
  for (std::size_t k = 0; k < cells; ++k) {
    map_x = base_x + origins[k].x();
    map_y = base_y + origins[k].y();
    cv::Mat cell_rgb(height, width, CV_8UC3, &colours[k * texels * 3]);
    cv::Mat cell_valid(height, width, CV_8UC1, &valid[k * texels]);
    cv::remap(rgb, cell_rgb, map_x, map_y, cv::INTER_LINEAR, cv::BORDER_CONSTANT);
    cv::remap(validity, cell_valid, map_x, map_y, cv::INTER_LINEAR, cv::BORDER_CONSTANT);
  }
  // The per-channel median of each texel's valid samples.
  std::array<std::vector<std::uint8_t>, 3> channel;
  for (auto& c : channel) c.resize(cells);
  for (std::size_t t = 0; t < texels; ++t) {
    std::size_t count = 0;
    for (std::size_t k = 0; k < cells; ++k) {
      if (valid[k * texels + t] != 255) continue;
      const std::uint8_t* colour = &colours[(k * texels + t) * 3];
      for (std::size_t c = 0; c < 3; ++c) channel[c][count] = colour[c];
      ++count;
    }
    if (count == 0) continue;
    const auto row = static_cast<int>(t / static_cast<std::size_t>(width));
    const auto col = static_cast<int>(t % static_cast<std::size_t>(width));
    cv::Vec3b& out = tile_rgb.at<cv::Vec3b>(row, col);
    for (std::size_t c = 0; c < 3; ++c) {
      const auto begin = channel[c].begin(), middle = begin + static_cast<long>(count / 2);
      std::nth_element(begin, middle, begin + static_cast<long>(count));
      out[static_cast<int>(c)] = *middle;
    }
    tile_mask.at<std::uint8_t>(row, col) = 255;
  }
}

TilingError tilingError(const cv::Mat& rgb, const cv::Mat& mask, const cv::Mat& tile_rgb,
                        const cv::Mat& tile_mask, const core::Lattice2& lattice) {
  if (tile_rgb.empty() || tile_rgb.type() != CV_8UC3 || tile_mask.size() != tile_rgb.size() ||
      !(lattice.cellArea() > 1e-9)) {
    throw core::Error("tilingError: needs a CV_8UC3 tile, its mask and a non-degenerate lattice");
  }
  // The tiling as the map shows it (the bitmap is the pattern's frame: identity); a full tile
  // is resampled without its mask, which would only cost the renormalisation.
  const bool full_tile = cv::countNonZero(tile_mask) == static_cast<int>(tile_mask.total());
  const match::Rendered tiling = match::renderPattern(tile_rgb, full_tile ? cv::Mat() : tile_mask,
                                                      lattice, {}, rgb.cols, rgb.rows);
  TilingError out{cv::Mat(rgb.size(), CV_32FC1, cv::Scalar(0)),
                  cv::Mat(rgb.size(), CV_8UC1, cv::Scalar(0))};
  for (int row = 0; row < rgb.rows; ++row) {
    const auto* bitmap = rgb.ptr<cv::Vec3b>(row);
    const auto* tiled = tiling.rgb.ptr<cv::Vec3b>(row);
    const auto* covered = tiling.covered.ptr<std::uint8_t>(row);
    const std::uint8_t* inside = mask.empty() ? nullptr : mask.ptr<std::uint8_t>(row);
    auto* error = out.error.ptr<float>(row);
    auto* valid = out.valid.ptr<std::uint8_t>(row);
    for (int col = 0; col < rgb.cols; ++col) {
      if ((inside != nullptr && inside[col] == 0) || covered[col] == 0) continue;
      int sum = 0;
      for (int c = 0; c < 3; ++c) {
        const int d = bitmap[col][c] - tiled[col][c];
        sum += d * d;
      }
      error[col] = std::sqrt(static_cast<float>(sum) * (1.0f / 3.0f));
      valid[col] = 255;
    }
  }
  return out;
}

}  // namespace tessera::pattern
