#include "tessera/pattern/overlays.h"

#include <algorithm>
#include <cstdint>

#include <opencv2/imgproc.hpp>

namespace tessera::pattern {

Overlays findOverlays(const cv::Mat& error, const cv::Mat& compared, const OverlayConfig& config) {
  Overlays out;
  out.unexplained = cv::Mat(error.size(), CV_8UC1, cv::Scalar(0));
  // The median error from a histogram of 1/8 grey level bins (a sort would cost more than all
  // the rest of the judgement).
  constexpr double kBinsPerLevel = 8.0;
  std::vector<int> histogram(static_cast<std::size_t>(256 * kBinsPerLevel) + 1, 0);
  int count = 0;
  for (int row = 0; row < error.rows; ++row) {
    const auto* e = error.ptr<float>(row);
    const auto* v = compared.ptr<std::uint8_t>(row);
    for (int col = 0; col < error.cols; ++col) {
      if (v[col] == 0) continue;
      ++histogram[std::min(histogram.size() - 1, static_cast<std::size_t>(e[col] * kBinsPerLevel))];
      ++count;
    }
  }
  if (count == 0) return out;
  std::size_t bin = 0;
  for (int below = 0; below + histogram[bin] <= count / 2; ++bin) below += histogram[bin];
  const double sigma = 1.4826 * (static_cast<double>(bin) + 0.5) / kBinsPerLevel;
  const double threshold = std::max(config.sigmas * sigma, config.min_error);

  // The error averaged over a few texels, so that an object's texels that happen to resemble
  // the surface still count as the object's; blobs with their holes filled.
  cv::Mat smooth;
  cv::blur(error, smooth, {7, 7});
  cv::Mat high = (smooth > threshold) & compared;
  if (cv::countNonZero(high) > 0) {
    std::vector<std::vector<cv::Point>> contours;
    cv::findContours(high, contours, cv::RETR_EXTERNAL, cv::CHAIN_APPROX_SIMPLE);
    for (std::size_t i = 0; i < contours.size(); ++i) {
      if (cv::contourArea(contours[i]) < config.min_px) continue;
      cv::drawContours(out.unexplained, contours, static_cast<int>(i), cv::Scalar(255), cv::FILLED);
      out.blobs.push_back(cv::boundingRect(contours[i]));
    }
    if (!out.blobs.empty()) {
      cv::dilate(out.unexplained, out.unexplained,
                 cv::getStructuringElement(cv::MORPH_ELLIPSE, {5, 5}));
      out.unexplained &= compared;
    }
  }
  std::sort(out.blobs.begin(), out.blobs.end(),
            [](const cv::Rect& p, const cv::Rect& q) { return p.area() > q.area(); });
  out.unexplained_share = cv::countNonZero(out.unexplained) / static_cast<double>(count);
  return out;
}

cv::Mat colourError(const cv::Mat& a, const cv::Mat& b) {
  cv::Mat error(a.size(), CV_32FC1);
  for (int row = 0; row < a.rows; ++row) {
    const auto* p = a.ptr<cv::Vec3b>(row);
    const auto* q = b.ptr<cv::Vec3b>(row);
    auto* e = error.ptr<float>(row);
    for (int col = 0; col < a.cols; ++col) {
      float sum = 0.0f;
      for (int c = 0; c < 3; ++c) {
        const float d = static_cast<float>(p[col][c]) - static_cast<float>(q[col][c]);
        sum += d * d;
      }
      e[col] = std::sqrt(sum / 3.0f);
    }
  }
  return error;
}

}  // namespace tessera::pattern
