// Shading of a periodic bitmap: a smooth gain field between the tiling and the bitmap.
#include "internal/shading.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include <opencv2/imgproc.hpp>

namespace tessera::pattern {

namespace {

// Rec. 601 luminance of a CV_8UC3 image as CV_32FC1 (the channel order does not matter for
// a gain shared by the three channels, only that both images use the same).
cv::Mat luminance(const cv::Mat& rgb) {
  cv::Mat grey;
  cv::cvtColor(rgb, grey, cv::COLOR_RGB2GRAY);
  grey.convertTo(grey, CV_32F);
  return grey;
}

cv::Mat scaledBy(const cv::Mat& rgb, const cv::Mat& gain, bool divide) {
  cv::Mat out(rgb.size(), CV_8UC3);
  for (int row = 0; row < rgb.rows; ++row) {
    const auto* in = rgb.ptr<cv::Vec3b>(row);
    const auto* g = gain.ptr<float>(row);
    auto* o = out.ptr<cv::Vec3b>(row);
    for (int col = 0; col < rgb.cols; ++col) {
      const float f = divide ? 1.0F / std::max(g[col], 1e-3F) : g[col];
      for (int c = 0; c < 3; ++c) {
        o[col][c] = cv::saturate_cast<std::uint8_t>(f * static_cast<float>(in[col][c]));
      }
    }
  }
  return out;
}

}  // namespace

cv::Mat wideBlur(const cv::Mat& image, double sigma) {
  // Three boxes of width w have variance 3 (w^2 - 1) / 12 (central limit; Wells 1986): each box
  // costs the same whatever its width, where a direct Gaussian of a wide sigma would not.
  const int half = std::max(
      1, static_cast<int>(std::lround(0.5 * (std::sqrt(4.0 * sigma * sigma + 1.0) - 1.0))));
  const cv::Size box(2 * half + 1, 2 * half + 1);
  cv::Mat out;
  cv::blur(image, out, box);
  cv::blur(out, out, box);
  cv::blur(out, out, box);
  return out;
}

cv::Mat estimateShading(const cv::Mat& rgb, const cv::Mat& tiled, const cv::Mat& valid,
                        double sigma) {
  cv::Mat m;
  cv::Mat(valid != 0).convertTo(m, CV_32F, 1.0 / 255.0);
  const cv::Mat bitmap = luminance(rgb), tiling = luminance(tiled);
  const cv::Mat cross = wideBlur(bitmap.mul(tiling).mul(m), sigma);
  const cv::Mat energy = wideBlur(tiling.mul(tiling).mul(m), sigma);
  // Where the window holds too little of the tiling to say (a plain dark tile, the bitmap's
  // border), the gain stays 1 rather than dividing noise.
  const float floor = 1.0F;  // grey level squared, a window's mean
  cv::Mat gain(rgb.size(), CV_32FC1);
  for (int row = 0; row < gain.rows; ++row) {
    const auto* c = cross.ptr<float>(row);
    const auto* e = energy.ptr<float>(row);
    auto* g = gain.ptr<float>(row);
    for (int col = 0; col < gain.cols; ++col) g[col] = e[col] > floor ? c[col] / e[col] : 1.0F;
  }
  const double mean = cv::mean(gain, valid)[0];
  if (mean > 1e-3) gain /= mean;
  return gain;
}

cv::Mat explainedByShading(const cv::Mat& rgb, const cv::Mat& tiled, const cv::Mat& shading,
                           const cv::Mat& valid, float min_error) {
  cv::Mat error;
  cv::absdiff(luminance(rgb), luminance(tiled).mul(shading), error);
  std::vector<float> sample;
  sample.reserve(error.total() / 16 + 1);
  for (int row = 0; row < error.rows; row += 4) {
    for (int col = 0; col < error.cols; col += 4) {
      if (valid.at<std::uint8_t>(row, col) != 0) sample.push_back(error.at<float>(row, col));
    }
  }
  float bound = min_error;
  if (!sample.empty()) {
    auto middle = sample.begin() + static_cast<long>(sample.size() / 2);
    std::nth_element(sample.begin(), middle, sample.end());
    bound = std::max(bound, 3.0F * *middle);
  }
  return valid & (error < bound);
}

double shadingSpread(const cv::Mat& shading, const cv::Mat& valid) {
  std::vector<float> values;
  values.reserve(shading.total() / 16 + 1);
  // Every 4th texel each way: the field is smooth.
  for (int row = 0; row < shading.rows; row += 4) {
    const auto* g = shading.ptr<float>(row);
    const std::uint8_t* v = valid.empty() ? nullptr : valid.ptr<std::uint8_t>(row);
    for (int col = 0; col < shading.cols; col += 4) {
      if (v == nullptr || v[col] != 0) values.push_back(g[col]);
    }
  }
  if (values.size() < 2) return 0.0;
  const auto at = [&values](double q) {
    auto it = values.begin() + static_cast<long>(q * static_cast<double>(values.size() - 1));
    std::nth_element(values.begin(), it, values.end());
    return static_cast<double>(*it);
  };
  return at(0.95) - at(0.05);
}

cv::Mat unshaded(const cv::Mat& rgb, const cv::Mat& shading) {
  return scaledBy(rgb, shading, true);
}

cv::Mat shaded(const cv::Mat& tiled, const cv::Mat& shading) {
  return scaledBy(tiled, shading, false);
}

}  // namespace tessera::pattern
