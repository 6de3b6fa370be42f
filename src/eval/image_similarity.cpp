#include "tessera/eval/image_similarity.h"

#include <algorithm>
#include <cmath>
#include <cstdint>

#include <opencv2/imgproc.hpp>

namespace tessera::eval {

namespace {

// Rec. 601 luma, in doubles: SSIM's variances are differences of nearly equal moments.
cv::Mat lumaOf(const cv::Mat& rgb) {
  cv::Mat grey;
  cv::cvtColor(rgb, grey, cv::COLOR_RGB2GRAY);
  grey.convertTo(grey, CV_64F);
  return grey;
}

// Mean of `image` over the mask pixels of each pixel's window (`smooth` applies the window):
// normalised convolution, so that pixels outside the mask never enter a mean.
cv::Mat maskedMean(const cv::Mat& image, const cv::Mat& weight, const cv::Mat& smoothed_weight,
                   void (*smooth)(const cv::Mat&, cv::Mat&)) {
  cv::Mat sum;
  smooth(image.mul(weight), sum);
  return sum / cv::max(smoothed_weight, 1e-6);
}

void gaussianWindow(const cv::Mat& in, cv::Mat& out) {
  cv::GaussianBlur(in, out, cv::Size(11, 11), 1.5, 1.5, cv::BORDER_CONSTANT);
}

void boxWindow(const cv::Mat& in, cv::Mat& out) {
  cv::boxFilter(in, out, -1, cv::Size(7, 7), cv::Point(-1, -1), false, cv::BORDER_CONSTANT);
}

// SSIM (Wang et al. 2004) of two luma images, its local moments over the mask only.
double maskedSsim(const cv::Mat& x, const cv::Mat& y, const cv::Mat& weight, const cv::Mat& mask) {
  constexpr double kC1 = (0.01 * 255) * (0.01 * 255), kC2 = (0.03 * 255) * (0.03 * 255);
  cv::Mat w;
  gaussianWindow(weight, w);
  const cv::Mat mx = maskedMean(x, weight, w, gaussianWindow);
  const cv::Mat my = maskedMean(y, weight, w, gaussianWindow);
  const cv::Mat vx = maskedMean(x.mul(x), weight, w, gaussianWindow) - mx.mul(mx);
  const cv::Mat vy = maskedMean(y.mul(y), weight, w, gaussianWindow) - my.mul(my);
  const cv::Mat cxy = maskedMean(x.mul(y), weight, w, gaussianWindow) - mx.mul(my);
  double sum = 0.0;
  std::size_t n = 0;
  for (int r = 0; r < mask.rows; ++r) {
    const auto* m = mask.ptr<std::uint8_t>(r);
    for (int c = 0; c < mask.cols; ++c) {
      if (m[c] == 0) continue;
      const double ax = mx.at<double>(r, c), ay = my.at<double>(r, c);
      const double sxx = std::max(0.0, vx.at<double>(r, c));
      const double syy = std::max(0.0, vy.at<double>(r, c));
      const double sxy = cxy.at<double>(r, c);
      sum +=
          (2 * ax * ay + kC1) * (2 * sxy + kC2) / ((ax * ax + ay * ay + kC1) * (sxx + syy + kC2));
      ++n;
    }
  }
  return n > 0 ? sum / static_cast<double>(n) : 0.0;
}

}  // namespace

std::optional<double> maskedPsnr(const cv::Mat& rendered, const cv::Mat& captured,
                                 const cv::Mat& mask) {
  double squared = 0.0;
  std::size_t count = 0;
  for (int y = 0; y < mask.rows; ++y) {
    const auto* a = rendered.ptr<cv::Vec3b>(y);
    const auto* b = captured.ptr<cv::Vec3b>(y);
    const auto* m = mask.ptr<std::uint8_t>(y);
    for (int x = 0; x < mask.cols; ++x) {
      if (m[x] == 0) continue;
      for (int c = 0; c < 3; ++c) {
        const double d = static_cast<double>(a[x][c]) - static_cast<double>(b[x][c]);
        squared += d * d;
      }
      count += 3;
    }
  }
  if (count == 0) return std::nullopt;
  const double mse = squared / static_cast<double>(count);
  return mse <= 0.0 ? 99.0 : 10.0 * std::log10(255.0 * 255.0 / mse);
}

std::optional<ImageSimilarity> compareImages(const cv::Mat& rendered, const cv::Mat& captured,
                                             const cv::Mat& mask) {
  const std::optional<double> psnr = maskedPsnr(rendered, captured, mask);
  if (!psnr) return std::nullopt;
  ImageSimilarity similarity;
  similarity.psnr_db = *psnr;
  cv::Mat weight;
  mask.convertTo(weight, CV_64F, 1.0 / 255.0);
  const cv::Mat x = lumaOf(rendered), y = lumaOf(captured);
  similarity.ssim = maskedSsim(x, y, weight, mask);

  cv::Mat box_weight;
  boxWindow(weight, box_weight);
  const cv::Mat band_x = x - maskedMean(x, weight, box_weight, boxWindow);
  const cv::Mat band_y = y - maskedMean(y, weight, box_weight, boxWindow);
  double xx = 0.0, yy = 0.0, xy = 0.0;
  for (int r = 0; r < mask.rows; ++r) {
    const auto* m = mask.ptr<std::uint8_t>(r);
    const auto* bx = band_x.ptr<double>(r);
    const auto* by = band_y.ptr<double>(r);
    for (int c = 0; c < mask.cols; ++c) {
      if (m[c] == 0) continue;
      xx += bx[c] * bx[c];
      yy += by[c] * by[c];
      xy += bx[c] * by[c];
    }
  }
  // Band-pass values have mean about zero: the correlation is taken about zero.
  if (xx > 0.0 && yy > 0.0) {
    similarity.detail_correlation = xy / std::sqrt(xx * yy);
    similarity.detail_energy_ratio = xx / yy;
    const double amplitude = std::sqrt(similarity.detail_energy_ratio);
    similarity.detail = similarity.detail_correlation * std::min(amplitude, 1.0 / amplitude);
  }
  return similarity;
}

}  // namespace tessera::eval
