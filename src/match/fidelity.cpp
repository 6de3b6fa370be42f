#include "tessera/match/fidelity.h"

#include <algorithm>
#include <cmath>
#include <cstdint>

#include <fmt/format.h>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "tessera/core/error.h"

namespace tessera::match {
namespace {

// x wrapped into [0, period): the same double as std::fmod's remainder brought into that range,
// at a fraction of its cost (a pattern is rendered for every texel of every candidate tiling).
// With n = floor(x / period), x - n period is exact (the two are within a factor of two), and
// a quotient rounded up across an integer is corrected by one period.
double wrap(double x, double period) {
  const double q = x / period;
  // floor(q), without the library call: truncation, one less below zero.
  auto n = static_cast<double>(static_cast<long long>(q));
  if (n > q) n -= 1.0;
  double r = x - n * period;
  if (r < 0.0) {
    r += period;
  } else if (r >= period) {
    r -= period;
  }
  return r;
}

// A pixel-centre sample point x lies on texel round(x); that texel exists for x in
// [-0.5, size - 0.5). In a tiled texture every point lies on one (after wrapping).
int nearestTexel(double x, int size, bool tiled) {
  const auto texel = static_cast<int>(std::floor(x + 0.5));
  if (!tiled) return texel;
  return texel >= size ? texel - size : texel;  // x was wrapped into [0, size)
}

void checkTexture(const cv::Mat& texture, const cv::Mat& texture_mask, int width, int height) {
  if (texture.empty() || texture.type() != CV_8UC3) {
    throw core::Error("renderThrough: the texture must be a non-empty CV_8UC3");
  }
  if (!texture_mask.empty() &&
      (texture_mask.type() != CV_8UC1 || texture_mask.size() != texture.size())) {
    throw core::Error("renderThrough: the texture mask must be CV_8UC1 of the texture's size");
  }
  if (width < 0 || height < 0) {
    throw core::Error(fmt::format("renderThrough: negative grid size {}x{}", width, height));
  }
}

// The texels bilinear sampling at (map_x, map_y) reads, within a texture of `size`: from the
// floor of the least coordinate to one past the floor of the largest. Texels beyond it weigh
// nothing in any sample, so sampling the window alone gives the same values.
cv::Rect sampledWindow(const cv::Mat& map_x, const cv::Mat& map_y, const cv::Size& size) {
  double x_low = 0, x_high = 0, y_low = 0, y_high = 0;
  cv::minMaxLoc(map_x, &x_low, &x_high);
  cv::minMaxLoc(map_y, &y_low, &y_high);
  // Clamped as doubles: a sample may lie anywhere.
  const auto within = [](double x, int last) {
    return static_cast<int>(std::clamp(x, -1.0, static_cast<double>(last) + 1.0));
  };
  const int x0 = std::max(0, within(std::floor(x_low), size.width - 1));
  const int y0 = std::max(0, within(std::floor(y_low), size.height - 1));
  const int x1 = std::min(size.width - 1, within(std::floor(x_high) + 1.0, size.width - 1));
  const int y1 = std::min(size.height - 1, within(std::floor(y_high) + 1.0, size.height - 1));
  if (x1 < x0 || y1 < y0) return {};
  return {x0, y0, x1 - x0 + 1, y1 - y0 + 1};
}

// Samples `texture` at texture pixel coordinates (map_x, map_y), wrapped into [0, size) when
// tiled; a texel is covered when the nearest texture texel exists and is valid.
Rendered sampleTexture(const cv::Mat& texture, const cv::Mat& texture_mask, const cv::Mat& map_x,
                       const cv::Mat& map_y, bool tiled) {
  Rendered out{cv::Mat(map_x.size(), CV_8UC3, cv::Scalar::all(0)),
               cv::Mat(map_x.size(), CV_8UC1, cv::Scalar(0))};
  // A whole tile repeated covers everything.
  if (tiled && texture_mask.empty()) out.covered.setTo(cv::Scalar(255));
  for (int row = 0; row < map_x.rows && !(tiled && texture_mask.empty()); ++row) {
    const auto* mx = map_x.ptr<float>(row);
    const auto* my = map_y.ptr<float>(row);
    auto* covered = out.covered.ptr<std::uint8_t>(row);
    for (int col = 0; col < map_x.cols; ++col) {
      const int tx = nearestTexel(mx[col], texture.cols, tiled);
      const int ty = nearestTexel(my[col], texture.rows, tiled);
      const bool inside = tx >= 0 && ty >= 0 && tx < texture.cols && ty < texture.rows;
      if (inside && (texture_mask.empty() || texture_mask.at<std::uint8_t>(ty, tx) != 0)) {
        covered[col] = 255;
      }
    }
  }

  const int border = tiled ? cv::BORDER_WRAP : cv::BORDER_REPLICATE;
  if (texture_mask.empty()) {
    cv::remap(texture, out.rgb, map_x, map_y, cv::INTER_LINEAR, border);
  } else {
    // Bilinear over the valid neighbours only (weights renormalised), so the colour of
    // masked-out texels never bleeds into a covered texel at the mask's edge. Untiled, only
    // the window of texels the samples touch is converted (a small patch placed in a large
    // stored texture needs a small part of it).
    const cv::Rect window = tiled ? cv::Rect(0, 0, texture.cols, texture.rows)
                                  : sampledWindow(map_x, map_y, texture.size());
    if (window.empty()) return out;  // every sample falls outside the texture
    cv::Mat colour, weight, weight3;
    texture(window).convertTo(colour, CV_32FC3);
    cv::threshold(texture_mask(window), weight, 0, 1, cv::THRESH_BINARY);
    weight.convertTo(weight, CV_32F);
    cv::merge(std::vector<cv::Mat>{weight, weight, weight}, weight3);
    const cv::Mat weighted_colour = colour.mul(weight3);
    const int masked_border = tiled ? cv::BORDER_WRAP : cv::BORDER_CONSTANT;
    // In strips of rows: each output texel depends on its own map entry only, so the values
    // are the same, and the float buffers stay small (whole, they held about 60 bytes a
    // texel at once: a floor tile's render, tens of MB, on each describing thread).
    constexpr int kStripRows = 64;
    cv::Mat shifted_x, shifted_y, sampled_colour, sampled_weight, blended;
    for (int first = 0; first < map_x.rows; first += kStripRows) {
      const cv::Range rows(first, std::min(map_x.rows, first + kStripRows));
      cv::Mat strip_x = map_x.rowRange(rows), strip_y = map_y.rowRange(rows);
      if (window.x != 0 || window.y != 0) {
        cv::subtract(strip_x, static_cast<double>(window.x), shifted_x);
        cv::subtract(strip_y, static_cast<double>(window.y), shifted_y);
        strip_x = shifted_x;
        strip_y = shifted_y;
      }
      cv::remap(weighted_colour, sampled_colour, strip_x, strip_y, cv::INTER_LINEAR, masked_border);
      cv::remap(weight3, sampled_weight, strip_x, strip_y, cv::INTER_LINEAR, masked_border);
      cv::divide(sampled_colour, cv::max(sampled_weight, 1e-6), blended);
      blended.convertTo(out.rgb.rowRange(rows), CV_8UC3);
    }
  }
  out.rgb.setTo(cv::Scalar::all(0), out.covered == 0);
  return out;
}

}  // namespace

Rendered renderThrough(const cv::Mat& texture, const cv::Mat& texture_mask,
                       const core::Similarity2& patch_to_texture, int width, int height,
                       bool tiled) {
  checkTexture(texture, texture_mask, width, height);
  if (tiled) {
    const core::Lattice2 cell{{texture.cols, 0.0}, {0.0, texture.rows}};
    return renderPattern(texture, texture_mask, cell, patch_to_texture, width, height);
  }
  cv::Mat map_x(height, width, CV_32FC1), map_y(height, width, CV_32FC1);
  for (int row = 0; row < height; ++row) {
    auto* mx = map_x.ptr<float>(row);
    auto* my = map_y.ptr<float>(row);
    for (int col = 0; col < width; ++col) {
      const Eigen::Vector2d p =
          patch_to_texture.apply({static_cast<double>(col), static_cast<double>(row)});
      mx[col] = static_cast<float>(p.x());
      my[col] = static_cast<float>(p.y());
    }
  }
  return sampleTexture(texture, texture_mask, map_x, map_y, false);
}

Rendered renderPattern(const cv::Mat& tile, const cv::Mat& tile_mask, const core::Lattice2& lattice,
                       const core::Similarity2& patch_to_frame, int width, int height) {
  checkTexture(tile, tile_mask, width, height);
  if (!(lattice.cellArea() > 1e-9)) {
    throw core::Error("renderPattern: the lattice's vectors are parallel or zero");
  }
  // Patch texel -> frame point q -> lattice coordinates c = L^-1 q -> tile pixel (c1 W, c2 H),
  // wrapped before the float conversion to keep sub-texel precision for far-off cells.
  const Eigen::Matrix2d to_lattice = lattice.basis().inverse();
  cv::Mat map_x(height, width, CV_32FC1), map_y(height, width, CV_32FC1);
  for (int row = 0; row < height; ++row) {
    auto* mx = map_x.ptr<float>(row);
    auto* my = map_y.ptr<float>(row);
    for (int col = 0; col < width; ++col) {
      const Eigen::Vector2d c =
          to_lattice * patch_to_frame.apply({static_cast<double>(col), static_cast<double>(row)});
      mx[col] = static_cast<float>(wrap(c.x() * tile.cols, tile.cols));
      my[col] = static_cast<float>(wrap(c.y() * tile.rows, tile.rows));
    }
  }
  return sampleTexture(tile, tile_mask, map_x, map_y, true);
}

Fidelity measureFidelity(const cv::Mat& patch_rgb, const cv::Mat& patch_mask,
                         const cv::Mat& texture, const cv::Mat& texture_mask,
                         const core::Similarity2& patch_to_texture, bool tiled) {
  if (patch_rgb.empty() || patch_rgb.type() != CV_8UC3) {
    throw core::Error("measureFidelity: the patch bitmap must be a non-empty CV_8UC3");
  }
  if (!patch_mask.empty() &&
      (patch_mask.type() != CV_8UC1 || patch_mask.size() != patch_rgb.size())) {
    throw core::Error("measureFidelity: the patch mask must be CV_8UC1 of the bitmap's size");
  }
  return measureFidelity(patch_rgb, patch_mask,
                         renderThrough(texture, texture_mask, patch_to_texture, patch_rgb.cols,
                                       patch_rgb.rows, tiled));
}

Fidelity measureFidelity(const cv::Mat& patch_rgb, const cv::Mat& patch_mask,
                         const Rendered& rendered) {
  if (rendered.rgb.size() != patch_rgb.size()) {
    throw core::Error("measureFidelity: the render is not of the patch's size");
  }
  std::size_t in_mask = 0, compared = 0;
  double squared_error = 0.0;
  for (int row = 0; row < patch_rgb.rows; ++row) {
    const auto* patch = patch_rgb.ptr<cv::Vec3b>(row);
    const auto* render = rendered.rgb.ptr<cv::Vec3b>(row);
    const auto* covered = rendered.covered.ptr<std::uint8_t>(row);
    const std::uint8_t* inside = patch_mask.empty() ? nullptr : patch_mask.ptr<std::uint8_t>(row);
    for (int col = 0; col < patch_rgb.cols; ++col) {
      if (inside != nullptr && inside[col] == 0) continue;
      ++in_mask;
      if (covered[col] == 0) continue;
      ++compared;
      for (int c = 0; c < 3; ++c) {
        const double d = static_cast<double>(patch[col][c]) - render[col][c];
        squared_error += d * d;
      }
    }
  }
  Fidelity fidelity;
  fidelity.texels = compared;
  if (compared == 0) return fidelity;
  fidelity.coverage = static_cast<double>(compared) / static_cast<double>(in_mask);
  const double mse = squared_error / (3.0 * static_cast<double>(compared));
  // Capped so that "identical" reads the same whatever the patch size.
  fidelity.psnr_db = mse > 0.0 ? std::min(kIdenticalPsnrDb, 10.0 * std::log10(255.0 * 255.0 / mse))
                               : kIdenticalPsnrDb;
  return fidelity;
}

}  // namespace tessera::match
