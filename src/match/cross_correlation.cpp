#include "tessera/match/cross_correlation.h"

#include <algorithm>
#include <cmath>
#include <cstdint>

#include <fmt/format.h>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "tessera/core/error.h"

namespace tessera::match {
namespace {

// Windows (and tiles) whose grey standard deviation is below this are flat: far below the
// quantisation noise of 8-bit images, so they hold no structure, and their NCC would be the
// ratio of two rounding errors.
constexpr double kFlatStdDev = 0.05;

void requireGrey(const cv::Mat& image, const char* function, const char* what) {
  if (image.empty() || image.type() != CV_32FC1) {
    throw core::Error(fmt::format("{}: the {} must be a non-empty CV_32FC1", function, what));
  }
}

}  // namespace

cv::Mat greyForCorrelation(const cv::Mat& rgb, const cv::Mat& mask) {
  if (rgb.empty() || rgb.type() != CV_8UC3) {
    throw core::Error("greyForCorrelation: the image must be a non-empty CV_8UC3");
  }
  if (!mask.empty() && (mask.type() != CV_8UC1 || mask.size() != rgb.size())) {
    throw core::Error("greyForCorrelation: the mask must be CV_8UC1 of the image's size");
  }
  cv::Mat colour, grey;
  rgb.convertTo(colour, CV_32FC3);
  cv::cvtColor(colour, grey, cv::COLOR_RGB2GRAY);
  if (!mask.empty()) {
    cv::Mat outside;
    cv::compare(mask, 0, outside, cv::CMP_EQ);
    const bool any_inside = cv::countNonZero(mask) > 0;
    grey.setTo(any_inside ? cv::mean(grey, mask)[0] : 0.0, outside);
  }
  return grey;
}

cv::Mat normalisedCrossCorrelation(const cv::Mat& image, const cv::Mat& tile) {
  requireGrey(image, "normalisedCrossCorrelation", "image");
  requireGrey(tile, "normalisedCrossCorrelation", "tile");
  if (tile.cols > image.cols || tile.rows > image.rows) {
    throw core::Error(fmt::format("normalisedCrossCorrelation: tile {}x{} larger than image {}x{}",
                                  tile.cols, tile.rows, image.cols, image.rows));
  }
  const cv::Size size(image.cols - tile.cols + 1, image.rows - tile.rows + 1);
  cv::Scalar tile_mean, tile_std;
  cv::meanStdDev(tile, tile_mean, tile_std);
  // matchTemplate answers 1 everywhere for a flat tile; it matches nothing.
  if (tile_std[0] < kFlatStdDev) return cv::Mat::zeros(size, CV_32FC1);

  cv::Mat ncc;
  cv::matchTemplate(image, tile, ncc, cv::TM_CCOEFF_NORMED);
  // Each window's spread from integral images in double, to zero flat windows ourselves.
  cv::Mat sum, square_sum;
  cv::integral(image, sum, square_sum, CV_64F, CV_64F);
  const double area = static_cast<double>(tile.total());
  const double min_variance = kFlatStdDev * kFlatStdDev;
  for (int y = 0; y < size.height; ++y) {
    auto* out = ncc.ptr<float>(y);
    const auto* s0 = sum.ptr<double>(y);
    const auto* s1 = sum.ptr<double>(y + tile.rows);
    const auto* q0 = square_sum.ptr<double>(y);
    const auto* q1 = square_sum.ptr<double>(y + tile.rows);
    for (int x = 0; x < size.width; ++x) {
      const int x1 = x + tile.cols;
      const double mean = (s1[x1] - s1[x] - s0[x1] + s0[x]) / area;
      const double variance = (q1[x1] - q1[x] - q0[x1] + q0[x]) / area - mean * mean;
      if (variance < min_variance || !std::isfinite(out[x])) out[x] = 0.0F;
    }
  }
  return ncc;
}

CorrelationPeak findTile(const cv::Mat& image, const cv::Mat& tile) {
  const cv::Mat ncc = normalisedCrossCorrelation(image, tile);
  double best = 0.0;
  cv::Point at;
  cv::minMaxLoc(ncc, nullptr, &best, nullptr, &at);
  return {at.x, at.y, best};
}

namespace {

// corr(a, b)(d) = sum_p a(p) b(p - d) for every shift d, at index d mod the spectra's size.
cv::Mat correlate(const cv::Mat& spectrum_a, const cv::Mat& spectrum_b) {
  cv::Mat product, out;
  cv::mulSpectrums(spectrum_a, spectrum_b, product, 0, /*conjB=*/true);
  cv::idft(product, out, cv::DFT_SCALE | cv::DFT_REAL_OUTPUT);
  return out;
}

cv::Mat spectrum(const cv::Mat& image, const cv::Size& padded) {
  cv::Mat canvas = cv::Mat::zeros(padded, CV_64FC1);
  image.convertTo(canvas(cv::Rect(0, 0, image.cols, image.rows)), CV_64F);
  cv::Mat out;
  cv::dft(canvas, out, cv::DFT_COMPLEX_OUTPUT);
  return out;
}

}  // namespace

CorrelationPeak findOverlap(const cv::Mat& fixed, const cv::Mat& fixed_mask, const cv::Mat& moving,
                            const cv::Mat& moving_mask, double min_overlap) {
  requireGrey(fixed, "findOverlap", "fixed image");
  requireGrey(moving, "findOverlap", "moving image");
  if (fixed_mask.size() != fixed.size() || moving_mask.size() != moving.size()) {
    throw core::Error("findOverlap: each mask must have its image's size");
  }
  // Every shift from the moving image's bottom-right touching the fixed one's top-left to its
  // top-left touching the bottom-right, without wrapping onto another.
  const cv::Size padded(cv::getOptimalDFTSize(fixed.cols + moving.cols - 1),
                        cv::getOptimalDFTSize(fixed.rows + moving.rows - 1));
  cv::Mat mf, mg;
  cv::Mat(fixed_mask != 0).convertTo(mf, CV_64F, 1.0 / 255.0);
  cv::Mat(moving_mask != 0).convertTo(mg, CV_64F, 1.0 / 255.0);
  cv::Mat f, g;
  fixed.convertTo(f, CV_64F);
  moving.convertTo(g, CV_64F);
  f = f.mul(mf), g = g.mul(mg);
  const cv::Mat F_m = spectrum(mf, padded), G_m = spectrum(mg, padded);
  const cv::Mat F = spectrum(f, padded), G = spectrum(g, padded);
  const cv::Mat F2 = spectrum(f.mul(f), padded), G2 = spectrum(g.mul(g), padded);
  const cv::Mat n = correlate(F_m, G_m);
  const cv::Mat sf = correlate(F, G_m), sg = correlate(F_m, G);
  const cv::Mat sff = correlate(F2, G_m), sgg = correlate(F_m, G2);
  const cv::Mat sfg = correlate(F, G);
  CorrelationPeak best;
  const auto index = [](int d, int size) { return d >= 0 ? d : d + size; };
  for (int y = -(moving.rows - 1); y < fixed.rows; ++y) {
    const int row = index(y, padded.height);
    for (int x = -(moving.cols - 1); x < fixed.cols; ++x) {
      const int col = index(x, padded.width);
      const double count = std::round(n.at<double>(row, col));
      if (count < std::max(2.0, min_overlap)) continue;
      const double mean_f = sf.at<double>(row, col), mean_g = sg.at<double>(row, col);
      const double var_f = sff.at<double>(row, col) - mean_f * mean_f / count;
      const double var_g = sgg.at<double>(row, col) - mean_g * mean_g / count;
      // Flat overlaps (no structure on one side) are not a placement.
      const double flat = count * kFlatStdDev * kFlatStdDev;
      if (var_f <= flat || var_g <= flat) continue;
      const double score =
          (sfg.at<double>(row, col) - mean_f * mean_g / count) / std::sqrt(var_f * var_g);
      if (score > best.score) best = {x, y, std::min(1.0, score)};
    }
  }
  return best;
}

CorrelationPeak refineOverlap(const cv::Mat& fixed, const cv::Mat& fixed_mask,
                              const cv::Mat& moving, const cv::Mat& moving_mask,
                              const CorrelationPeak& start, int radius, double min_overlap) {
  requireGrey(fixed, "refineOverlap", "fixed image");
  requireGrey(moving, "refineOverlap", "moving image");
  CorrelationPeak best;
  for (int y = start.y - radius; y <= start.y + radius; ++y) {
    for (int x = start.x - radius; x <= start.x + radius; ++x) {
      // fixed(p) against moving(p - (x, y)) over the rows and columns both have.
      const int row0 = std::max(0, y), row1 = std::min(fixed.rows, y + moving.rows);
      const int col0 = std::max(0, x), col1 = std::min(fixed.cols, x + moving.cols);
      double count = 0, sf = 0, sg = 0, sff = 0, sgg = 0, sfg = 0;
      for (int r = row0; r < row1; ++r) {
        const auto* f = fixed.ptr<float>(r);
        const auto* g = moving.ptr<float>(r - y) - x;
        const auto* mf = fixed_mask.ptr<std::uint8_t>(r);
        const auto* mg = moving_mask.ptr<std::uint8_t>(r - y) - x;
        for (int c = col0; c < col1; ++c) {
          if (mf[c] == 0 || mg[c] == 0) continue;
          const double a = f[c], b = g[c];
          count += 1, sf += a, sg += b, sff += a * a, sgg += b * b, sfg += a * b;
        }
      }
      if (count < std::max(2.0, min_overlap)) continue;
      const double var_f = sff - sf * sf / count, var_g = sgg - sg * sg / count;
      const double flat = count * kFlatStdDev * kFlatStdDev;
      if (var_f <= flat || var_g <= flat) continue;
      const double score = (sfg - sf * sg / count) / std::sqrt(var_f * var_g);
      if (score > best.score) best = {x, y, std::min(1.0, score)};
    }
  }
  return best;
}

}  // namespace tessera::match
