#pragma once
// Colour Coherence Vectors (Pass et al.), the cascade's cheap prefilter: blur, quantise each
// pixel's colour into one of levels^3 joint colour bins, label 8-connected components of equal
// bin (OpenCV's connected-component labelling), and count per bin the pixels in coherent
// components (size >= s, alpha) and in the rest (beta). The vector keeps alpha/N and beta/N, so
// the published distance between images of sizes N1 and N2,
//   sum_i |alpha1_i/N1 - alpha2_i/N2| + |beta1_i/N1 - beta2_i/N2|,
// is the L1 distance of two vectors (0 for equal images, at most 2).
#include <cstddef>
#include <vector>

#include <opencv2/core/mat.hpp>

namespace tessera::match {

struct CcvConfig {
  double blur_sigma_px = 1.0;  // Gaussian blur before quantising (0: none)
  int levels = 4;              // per channel: levels^3 colour bins
  // A component is coherent when it holds at least s = max(min_coherent_px,
  // coherent_fraction * N) pixels. Pass et al. use 1 % of the image; tessera compares bitmaps of
  // one texel size but of very different extents (a crop against a whole wall), where a share of
  // the image would call the same blob coherent in one and not in the other: so by default s is
  // a fixed 50 texels, as in the published code.
  double coherent_fraction = 0.0;
  int min_coherent_px = 50;
  // Divide each channel by its mean over the mask (times 128) before quantising, so that an
  // exposure change between two sightings does not move every pixel to another bin.
  bool normalise_exposure = true;
};

struct Ccv {
  // [alpha_0 / N, ..., alpha_{B-1} / N, beta_0 / N, ..., beta_{B-1} / N], B = levels^3.
  std::vector<float> values;
  std::size_t pixels = 0;  // N: the pixels inside the mask
};

// The CCV of an RGB image (CV_8UC3) over `mask` (CV_8UC1, non-zero = inside; empty: all).
// Pixels outside the mask belong to no component. Throws core::Error on an empty image.
Ccv computeCcv(const cv::Mat& rgb, const cv::Mat& mask, const CcvConfig& config = {});

// The published distance (L1 of the normalised vectors). Vectors must have equal length.
double ccvDistance(const std::vector<float>& a, const std::vector<float>& b);

// The length of the vectors a config produces: 2 levels^3.
inline std::size_t ccvLength(const CcvConfig& config) {
  const auto l = static_cast<std::size_t>(config.levels);
  return 2 * l * l * l;
}

}  // namespace tessera::match
