#include "tessera/pattern/autocorrelation.h"

#include <algorithm>
#include <cmath>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "tessera/core/error.h"

namespace tessera::pattern {

namespace {

// The spectrum of `image` zero-padded to `padded` (real input, CCS-packed output).
cv::Mat spectrum(const cv::Mat& image, cv::Size padded) {
  cv::Mat big(padded, CV_32FC1, cv::Scalar(0));
  image.copyTo(big(cv::Rect(0, 0, image.cols, image.rows)));
  cv::Mat out;
  cv::dft(big, out, 0, image.rows);  // rows below the image are zero: skip them
  return out;
}

// corr(a, b)(d) = sum_x a(x) b(x + d) = IDFT(conj(A) B), real, with shift d at (d mod size).
cv::Mat correlation(const cv::Mat& spectrum_a, const cv::Mat& spectrum_b) {
  cv::Mat product, out;
  cv::mulSpectrums(spectrum_b, spectrum_a, product, 0, /*conjB=*/true);
  cv::idft(product, out, cv::DFT_SCALE | cv::DFT_REAL_OUTPUT);
  return out;
}

// The value of a circular correlation at shift (dx, dy), possibly negative.
float at(const cv::Mat& circular, int dx, int dy) {
  const int x = dx >= 0 ? dx : circular.cols + dx;
  const int y = dy >= 0 ? dy : circular.rows + dy;
  return circular.at<float>(y, x);
}

}  // namespace

double Autocorrelation::sample(double dx, double dy) const {
  const double x = dx + radius_x, y = dy + radius_y;
  const int x0 = static_cast<int>(std::floor(x)), y0 = static_cast<int>(std::floor(y));
  if (x0 < 0 || y0 < 0 || x0 + 1 >= rho.cols || y0 + 1 >= rho.rows) return -1.0;
  const double fx = x - x0, fy = y - y0;
  const double r00 = rho.at<float>(y0, x0), r01 = rho.at<float>(y0, x0 + 1);
  const double r10 = rho.at<float>(y0 + 1, x0), r11 = rho.at<float>(y0 + 1, x0 + 1);
  if (std::min({r00, r01, r10, r11}) <= -1.0) return -1.0;
  return (1 - fy) * ((1 - fx) * r00 + fx * r01) + fy * ((1 - fx) * r10 + fx * r11);
}

Autocorrelation autocorrelate(const cv::Mat& grey, const cv::Mat& mask, double min_overlap) {
  if (grey.empty() || grey.type() != CV_32FC1) {
    throw core::Error("autocorrelate: the image must be a non-empty CV_32FC1");
  }
  if (!mask.empty() && (mask.type() != CV_8UC1 || mask.size() != grey.size())) {
    throw core::Error("autocorrelate: the mask must be CV_8UC1 of the image's size");
  }
  cv::Mat m(grey.size(), CV_32FC1, cv::Scalar(1));
  if (!mask.empty()) {
    m.setTo(0.0f, mask == 0);
  }
  const double valid = cv::sum(m)[0];
  const bool full = valid >= static_cast<double>(grey.total());
  Autocorrelation out;
  out.radius_x = grey.cols / 2;
  out.radius_y = grey.rows / 2;
  out.rho = cv::Mat(2 * out.radius_y + 1, 2 * out.radius_x + 1, CV_32FC1, cv::Scalar(-1));
  if (valid < 1.0) return out;

  const double mean = cv::sum(grey.mul(m))[0] / valid;
  const cv::Mat f = (grey - mean).mul(m);
  const cv::Mat f2 = f.mul(f);
  // Padded so that the shifts kept (up to the radius) never wrap: a circular correlation over
  // P texels holds the linear one at d and at d - P, and the latter is empty when
  // P >= size + radius.
  const cv::Size padded(cv::getOptimalDFTSize(grey.cols + out.radius_x + 1),
                        cv::getOptimalDFTSize(grey.rows + out.radius_y + 1));
  const cv::Mat F = spectrum(f, padded);
  const cv::Mat ff = correlation(F, F);  // sum f(x) f(x+d)
  // Energies sum f(x)^2 m(x+d) and sum m(x) f(x+d)^2, and the overlap count: by correlation
  // with the mask in general; over a full mask the overlap is a rectangle, whose sums an
  // integral image gives without two more spectra.
  cv::Mat f2m, mm, f2_sums;
  if (full) {
    cv::integral(f2, f2_sums, CV_64F);
  } else {
    const cv::Mat M = spectrum(m, padded), F2 = spectrum(f2, padded);
    f2m = correlation(F2, M);  // sum f(x)^2 m(x+d); sum m(x) f(x+d)^2 is at -d
    mm = correlation(M, M);
  }
  // Sum of f^2 over the texels x with x and x + d both inside the image.
  const auto rectangleEnergy = [&](int dx, int dy) {
    const int x0 = std::max(0, -dx), x1 = grey.cols - std::max(0, dx);
    const int y0 = std::max(0, -dy), y1 = grey.rows - std::max(0, dy);
    return f2_sums.at<double>(y1, x1) - f2_sums.at<double>(y0, x1) - f2_sums.at<double>(y1, x0) +
           f2_sums.at<double>(y0, x0);
  };
  const double min_count = std::max(1.0, min_overlap * valid);
  for (int dy = -out.radius_y; dy <= out.radius_y; ++dy) {
    auto* row = out.rho.ptr<float>(out.radius_y + dy);
    for (int dx = -out.radius_x; dx <= out.radius_x; ++dx) {
      double count = 0.0, e1 = 0.0, e2 = 0.0;
      if (full) {
        count = static_cast<double>(grey.cols - std::abs(dx)) * (grey.rows - std::abs(dy));
        if (count < min_count) continue;
        e1 = rectangleEnergy(dx, dy);
        e2 = rectangleEnergy(-dx, -dy);
      } else {
        count = at(mm, dx, dy);
        if (count < min_count) continue;
        e1 = at(f2m, dx, dy);
        e2 = at(f2m, -dx, -dy);
      }
      if (e1 <= 1e-9 || e2 <= 1e-9) continue;
      const double r = at(ff, dx, dy) / std::sqrt(e1 * e2);
      row[out.radius_x + dx] = static_cast<float>(std::clamp(r, -1.0, 1.0));
    }
  }
  return out;
}

}  // namespace tessera::pattern
