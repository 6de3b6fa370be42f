#include "tessera/pattern/autocorrelation.h"

#include <cmath>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

namespace tessera::pattern {
namespace {

// The definition, summed directly and without wrapping: rho(d) over the texels valid at x and
// at x + d inside the image, with f the grey minus its mean over the mask.
double directRho(const cv::Mat& grey, const cv::Mat& mask, int dx, int dy) {
  double sum = 0.0, count = 0.0;
  for (int y = 0; y < grey.rows; ++y) {
    for (int x = 0; x < grey.cols; ++x) {
      if (mask.at<uchar>(y, x)) sum += grey.at<float>(y, x), count += 1;
    }
  }
  const double mean = sum / count;
  double ff = 0.0, e1 = 0.0, e2 = 0.0;
  for (int y = 0; y < grey.rows; ++y) {
    for (int x = 0; x < grey.cols; ++x) {
      const int u = x + dx, v = y + dy;
      if (u < 0 || v < 0 || u >= grey.cols || v >= grey.rows) continue;
      if (!mask.at<uchar>(y, x) || !mask.at<uchar>(v, u)) continue;
      const double a = grey.at<float>(y, x) - mean, b = grey.at<float>(v, u) - mean;
      ff += a * b, e1 += a * a, e2 += b * b;
    }
  }
  return ff / std::sqrt(e1 * e2);
}

TEST(Autocorrelation, MatchesTheNonCircularDirectSumUnderAMask) {
  cv::RNG rng(7);
  cv::Mat grey(24, 31, CV_32FC1);
  rng.fill(grey, cv::RNG::UNIFORM, 0.0, 255.0);
  cv::Mat mask(grey.size(), CV_8UC1, cv::Scalar(255));
  cv::circle(mask, {8, 16}, 6, cv::Scalar(0), cv::FILLED);  // a hole
  mask(cv::Rect(25, 0, 6, 10)).setTo(0);                    // and a cut corner
  const Autocorrelation acf = autocorrelate(grey, mask, 0.2);
  EXPECT_NEAR(acf.at(0, 0), 1.0, 1e-4);
  int compared = 0;
  for (int dy = -acf.radius_y; dy <= acf.radius_y; ++dy) {
    for (int dx = -acf.radius_x; dx <= acf.radius_x; ++dx) {
      if (acf.at(dx, dy) <= -1.0f) continue;  // too little overlap
      EXPECT_NEAR(acf.at(dx, dy), directRho(grey, mask, dx, dy), 1e-3) << dx << "," << dy;
      ++compared;
    }
  }
  EXPECT_GT(compared, 300);
}

TEST(Autocorrelation, FindsAPeriodThroughAMask) {
  cv::Mat grey(64, 96, CV_32FC1);
  for (int y = 0; y < grey.rows; ++y) {
    for (int x = 0; x < grey.cols; ++x) {
      grey.at<float>(y, x) = static_cast<float>(100 + 60 * std::sin(2 * M_PI * x / 12.0) +
                                                30 * std::cos(2 * M_PI * y / 8.0));
    }
  }
  cv::Mat mask(grey.size(), CV_8UC1, cv::Scalar(255));
  mask(cv::Rect(0, 0, 48, 32)).setTo(0);  // a quarter gone
  const Autocorrelation acf = autocorrelate(grey, mask);
  EXPECT_NEAR(acf.at(12, 0), 1.0, 1e-3);
  EXPECT_NEAR(acf.at(0, 8), 1.0, 1e-3);
  EXPECT_LT(acf.at(6, 0), 0.0);
}

}  // namespace
}  // namespace tessera::pattern
