#pragma once
// Internal to the pattern module: a bitmap as tile x shading, where the shading is a smooth
// gain field (the light's fall-off across a floor, a spotlight on a wall). The lattice is
// judged on the bitmap divided by its shading, and the map shows tile x shading.
#include <opencv2/core/mat.hpp>

namespace tessera::pattern {

// A Gaussian blur of standard deviation `sigma`, approximated by three box filters.
cv::Mat wideBlur(const cv::Mat& image, double sigma);

// The gain g(x) that best scales `tiled` (the tiling, CV_8UC3) to `rgb` (CV_8UC3) in the
// least-squares sense over a Gaussian window of `sigma` texels around x, on luminance:
// g = blur(m Y_bitmap Y_tiled) / blur(m Y_tiled^2), m the texels both have (`valid`, CV_8UC1).
// Scaled to mean 1 over the valid texels (the tile carries the mean brightness). CV_32FC1 of
// the bitmap's size; texels far from any valid one take the nearest window's estimate.
cv::Mat estimateShading(const cv::Mat& rgb, const cv::Mat& tiled, const cv::Mat& valid,
                        double sigma);

// The texels of `valid` that the shaded tiling explains (CV_8UC1, 255): luminance within
// max(min_error, 3 x the median error) of the bitmap's. An occluder or a stain is left out,
// so that the shading fitted without it does not follow it.
cv::Mat explainedByShading(const cv::Mat& rgb, const cv::Mat& tiled, const cv::Mat& shading,
                           const cv::Mat& valid, float min_error = 12.0F);

// The spread of a shading field: its 95th minus its 5th percentile over the valid texels
// (CV_8UC1 `valid`, empty: all), as a fraction (0.3: the light varies by 30 %).
double shadingSpread(const cv::Mat& shading, const cv::Mat& valid);

// rgb / shading, texel by texel, saturated to 8 bits: the bitmap under even light.
cv::Mat unshaded(const cv::Mat& rgb, const cv::Mat& shading);

// tiled x shading, saturated to 8 bits: what the map shows.
cv::Mat shaded(const cv::Mat& tiled, const cv::Mat& shading);

}  // namespace tessera::pattern
