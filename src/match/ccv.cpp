#include "tessera/match/ccv.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include <fmt/format.h>
#include <opencv2/imgproc.hpp>

#include "tessera/core/error.h"

namespace tessera::match {
namespace {

cv::Mat maskOrAll(const cv::Mat& rgb, const cv::Mat& mask) {
  if (mask.empty()) return cv::Mat(rgb.size(), CV_8UC1, cv::Scalar(255));
  if (mask.type() != CV_8UC1 || mask.size() != rgb.size()) {
    throw core::Error(fmt::format("computeCcv: the mask must be CV_8UC1 of the image's size {}x{}",
                                  rgb.cols, rgb.rows));
  }
  return mask;
}

// Float colours blurred only among pixels inside the mask (normalised convolution), so that
// the colour of whatever lies outside a patch does not bleed into its border pixels.
cv::Mat blurredInside(const cv::Mat& rgb, const cv::Mat& mask, double sigma_px) {
  cv::Mat colour;
  rgb.convertTo(colour, CV_32FC3);
  if (sigma_px <= 0.0) return colour;
  cv::Mat weight, blurred_weight, weight3, blurred_weight3, blurred_colour, result;
  cv::threshold(mask, weight, 0, 1, cv::THRESH_BINARY);
  weight.convertTo(weight, CV_32F);
  cv::merge(std::vector<cv::Mat>{weight, weight, weight}, weight3);
  cv::GaussianBlur(colour.mul(weight3), blurred_colour, cv::Size(), sigma_px);
  cv::GaussianBlur(weight, blurred_weight, cv::Size(), sigma_px);
  cv::merge(std::vector<cv::Mat>{blurred_weight, blurred_weight, blurred_weight}, blurred_weight3);
  cv::divide(blurred_colour, cv::max(blurred_weight3, 1e-6), result);
  return result;
}

// Joint colour bin of every pixel inside the mask: r L^2 + g L + b for per-channel levels
// r, g, b in [0, L); -1 outside the mask.
cv::Mat colourBins(const cv::Mat& colour, const cv::Mat& mask, const CcvConfig& config) {
  cv::Vec3d gain(1.0, 1.0, 1.0);
  if (config.normalise_exposure) {
    const cv::Scalar mean = cv::mean(colour, mask);
    for (int c = 0; c < 3; ++c) gain[c] = mean[c] > 1e-6 ? 128.0 / mean[c] : 1.0;
  }
  const int levels = config.levels;
  cv::Mat bins(colour.size(), CV_32SC1, cv::Scalar(-1));
  for (int y = 0; y < colour.rows; ++y) {
    const auto* in = colour.ptr<cv::Vec3f>(y);
    const auto* inside = mask.ptr<std::uint8_t>(y);
    auto* out = bins.ptr<int>(y);
    for (int x = 0; x < colour.cols; ++x) {
      if (inside[x] == 0) continue;
      int bin = 0;
      for (int c = 0; c < 3; ++c) {
        const double v = std::clamp(in[x][c] * gain[c], 0.0, 255.0);
        bin = bin * levels + std::min(levels - 1, static_cast<int>(v * levels / 256.0));
      }
      out[x] = bin;
    }
  }
  return bins;
}

}  // namespace

Ccv computeCcv(const cv::Mat& rgb, const cv::Mat& mask, const CcvConfig& config) {
  if (rgb.empty()) throw core::Error("computeCcv: empty image");
  if (rgb.type() != CV_8UC3) throw core::Error("computeCcv: the image must be CV_8UC3 (RGB)");
  if (config.levels < 1 || config.levels > 64) {
    throw core::Error(fmt::format("computeCcv: levels must be in [1, 64], got {}", config.levels));
  }
  const cv::Mat inside = maskOrAll(rgb, mask);
  const std::size_t bin_count = ccvLength(config) / 2;
  Ccv ccv;
  ccv.values.assign(2 * bin_count, 0.0F);
  ccv.pixels = static_cast<std::size_t>(cv::countNonZero(inside));
  if (ccv.pixels == 0) return ccv;

  const cv::Mat bins = colourBins(blurredInside(rgb, inside, config.blur_sigma_px), inside, config);
  std::vector<std::size_t> histogram(bin_count, 0);
  for (int y = 0; y < bins.rows; ++y) {
    const int* row = bins.ptr<int>(y);
    for (int x = 0; x < bins.cols; ++x) {
      if (row[x] >= 0) ++histogram[static_cast<std::size_t>(row[x])];
    }
  }

  const double n = static_cast<double>(ccv.pixels);
  const double s =
      std::max(static_cast<double>(config.min_coherent_px), config.coherent_fraction * n);
  cv::Mat members, labels, stats, centroids;
  for (std::size_t bin = 0; bin < bin_count; ++bin) {
    if (histogram[bin] == 0) continue;
    std::size_t coherent = 0;
    // A bin with fewer than s pixels cannot hold a coherent component: skip the labelling.
    if (static_cast<double>(histogram[bin]) >= s) {
      cv::compare(bins, static_cast<int>(bin), members, cv::CMP_EQ);
      const int count =
          cv::connectedComponentsWithStats(members, labels, stats, centroids, 8, CV_32S);
      for (int label = 1; label < count; ++label) {  // label 0 is the background
        const int area = stats.at<int>(label, cv::CC_STAT_AREA);
        if (area >= s) coherent += static_cast<std::size_t>(area);
      }
    }
    ccv.values[bin] = static_cast<float>(static_cast<double>(coherent) / n);
    ccv.values[bin_count + bin] =
        static_cast<float>(static_cast<double>(histogram[bin] - coherent) / n);
  }
  return ccv;
}

double ccvDistance(const std::vector<float>& a, const std::vector<float>& b) {
  if (a.size() != b.size()) {
    throw core::Error(
        fmt::format("ccvDistance: vectors of different lengths ({} and {})", a.size(), b.size()));
  }
  double sum = 0.0;
  for (std::size_t i = 0; i < a.size(); ++i) sum += std::abs(static_cast<double>(a[i]) - b[i]);
  return sum;
}

}  // namespace tessera::match
