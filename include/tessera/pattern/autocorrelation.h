#pragma once
// Autocorrelation of a grey image over its valid mask, not circular: the image and its mask
// are zero-padded to at least twice their size before the FFTs, so a shift never wraps one
// edge onto the other. Each shift d is normalised by what overlaps at d:
//   rho(d) = sum f(x) f(x+d) / sqrt(sum f(x)^2 m(x+d) * sum m(x) f(x+d)^2),
// over the texels valid both at x and at x + d, with f the grey minus its mean over the mask
// and m the mask, so rho(0) = 1 and a texture that repeats with period d has rho(d) near 1
// however much of the image is masked out.
#include <opencv2/core/mat.hpp>

namespace tessera::pattern {

struct Autocorrelation {
  // rho at shift (dx, dy) for |dx| <= radius_x, |dy| <= radius_y, stored at
  // (radius_y + dy, radius_x + dx); shifts whose overlap is below the minimum hold -1.
  cv::Mat rho;  // CV_32FC1
  int radius_x = 0, radius_y = 0;

  float at(int dx, int dy) const { return rho.at<float>(radius_y + dy, radius_x + dx); }
  bool contains(int dx, int dy) const {
    return dx >= -radius_x && dx <= radius_x && dy >= -radius_y && dy <= radius_y;
  }
  // Bilinear rho at a sub-texel shift; -1 outside.
  double sample(double dx, double dy) const;
};

// `grey` CV_32FC1; `mask` CV_8UC1 (0 = not valid; empty: all valid). Shifts up to half the
// image each way; a shift whose overlap holds fewer than `min_overlap` of the valid texels
// gets -1.
Autocorrelation autocorrelate(const cv::Mat& grey, const cv::Mat& mask, double min_overlap = 0.2);

}  // namespace tessera::pattern
