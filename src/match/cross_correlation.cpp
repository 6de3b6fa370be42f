#include "tessera/match/cross_correlation.h"

#include <cmath>

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

void requireGrey(const cv::Mat& image, const char* what) {
  if (image.empty() || image.type() != CV_32FC1) {
    throw core::Error(
        fmt::format("normalisedCrossCorrelation: the {} must be a non-empty CV_32FC1", what));
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
  requireGrey(image, "image");
  requireGrey(tile, "tile");
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

}  // namespace tessera::match
