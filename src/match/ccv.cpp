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
  if (sigma_px <= 0.0) {
    rgb.convertTo(colour, CV_32FC3);
    return colour;
  }
  // The colours with those outside the mask zeroed, and the mask as weights, both blurred;
  // their ratio is the blurred colour. Only pixels inside the mask are binned, so only theirs
  // is computed.
  cv::Mat weight, blurred_weight, blurred_colour;
  cv::Mat inside_colour(rgb.size(), CV_8UC3, cv::Scalar::all(0));
  rgb.copyTo(inside_colour, mask);
  inside_colour.convertTo(colour, CV_32FC3);
  cv::threshold(mask, weight, 0, 1, cv::THRESH_BINARY);
  weight.convertTo(weight, CV_32F);
  cv::GaussianBlur(colour, blurred_colour, cv::Size(), sigma_px);
  cv::GaussianBlur(weight, blurred_weight, cv::Size(), sigma_px);
  cv::Mat result(rgb.size(), CV_32FC3, cv::Scalar::all(0));
  for (int y = 0; y < rgb.rows; ++y) {
    const auto* inside = mask.ptr<std::uint8_t>(y);
    const auto* sum = blurred_colour.ptr<cv::Vec3f>(y);
    const auto* total = blurred_weight.ptr<float>(y);
    auto* out = result.ptr<cv::Vec3f>(y);
    for (int x = 0; x < rgb.cols; ++x) {
      if (inside[x] == 0) continue;
      const float w = std::max(total[x], 1e-6F);
      out[x] = cv::Vec3f(sum[x][0] / w, sum[x][1] / w, sum[x][2] / w);
    }
  }
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

// A connected component (8-neighbours) of pixels of one colour bin.
struct SameBinComponent {
  int bin = 0;
  std::size_t pixels = 0;
};

// Every such component of `bins` (CV_32S; negative: outside), in one pass of union-find over
// the pixels rather than one labelling of the whole image per bin.
std::vector<SameBinComponent> sameBinComponents(const cv::Mat& bins) {
  const int width = bins.cols;
  std::vector<int> parent(bins.total(), -1);  // -1: outside; a root is its own parent
  const auto root = [&parent](int i) {
    while (parent[static_cast<std::size_t>(i)] != i) {
      const int up = parent[static_cast<std::size_t>(parent[static_cast<std::size_t>(i)])];
      parent[static_cast<std::size_t>(i)] = up;  // path halving
      i = up;
    }
    return i;
  };
  const auto join = [&](int a, int b) {
    a = root(a);
    b = root(b);
    if (a != b) parent[static_cast<std::size_t>(std::max(a, b))] = std::min(a, b);
  };
  for (int y = 0; y < bins.rows; ++y) {
    const int* row = bins.ptr<int>(y);
    const int* above = y > 0 ? bins.ptr<int>(y - 1) : nullptr;
    for (int x = 0; x < width; ++x) {
      const int bin = row[x];
      if (bin < 0) continue;
      const int i = y * width + x;
      parent[static_cast<std::size_t>(i)] = i;
      // The neighbours already visited: left, and the three above.
      if (x > 0 && row[x - 1] == bin) join(i, i - 1);
      if (above == nullptr) continue;
      for (int dx = -1; dx <= 1; ++dx) {
        if (x + dx >= 0 && x + dx < width && above[x + dx] == bin) join(i, i - width + dx);
      }
    }
  }
  std::vector<SameBinComponent> components;
  std::vector<int> component_of(parent.size(), -1);
  const int* all = bins.ptr<int>(0);  // continuous: colourBins allocates it
  for (std::size_t i = 0; i < parent.size(); ++i) {
    if (parent[i] < 0) continue;
    const auto r = static_cast<std::size_t>(root(static_cast<int>(i)));
    if (component_of[r] < 0) {
      component_of[r] = static_cast<int>(components.size());
      components.push_back({all[r], 0});
    }
    ++components[static_cast<std::size_t>(component_of[r])].pixels;
  }
  return components;
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
  std::vector<std::size_t> histogram(bin_count, 0), coherent(bin_count, 0);
  const double n = static_cast<double>(ccv.pixels);
  const double s =
      std::max(static_cast<double>(config.min_coherent_px), config.coherent_fraction * n);
  for (const SameBinComponent& component : sameBinComponents(bins)) {
    const auto bin = static_cast<std::size_t>(component.bin);
    histogram[bin] += component.pixels;
    if (static_cast<double>(component.pixels) >= s) coherent[bin] += component.pixels;
  }
  for (std::size_t bin = 0; bin < bin_count; ++bin) {
    ccv.values[bin] = static_cast<float>(static_cast<double>(coherent[bin]) / n);
    ccv.values[bin_count + bin] =
        static_cast<float>(static_cast<double>(histogram[bin] - coherent[bin]) / n);
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
