#pragma once
// How closely a rendered view matches the captured frame over a mask of pixels
// (docs/METRICS.md, "View PSNR, SSIM and detail"): PSNR measures colour error, SSIM local
// structure, and the detail score whether the fine detail the camera saw is there, in its
// place, and no stronger or weaker than it was (blur, misplaced detail and added artefacts
// each lower it).
#include <optional>

#include <opencv2/core/mat.hpp>

namespace tessera::eval {

struct ImageSimilarity {
  double psnr_db = 0.0;  // 8-bit RGB; identical pixels give 99 dB
  double ssim = 0.0;     // of the luma, Gaussian window (sigma 1.5 px), over the mask
  // Band-pass luma: each pixel minus the mean of its 7 x 7 neighbours in the mask. Correlation
  // of the render's band-pass with the frame's over the mask, and the ratio of their energies
  // (sum of squares: below 1 when the render is blurred, above when it adds detail).
  double detail_correlation = 0.0;
  double detail_energy_ratio = 0.0;
  // detail_correlation * min(sqrt(ratio), 1 / sqrt(ratio)): 1 only for the same detail at the
  // same strength.
  double detail = 0.0;
};

// `rendered` and `captured` CV_8UC3 RGB of one size, `mask` CV_8UC1; nothing when the mask
// is empty.
std::optional<ImageSimilarity> compareImages(const cv::Mat& rendered, const cv::Mat& captured,
                                             const cv::Mat& mask);

// The PSNR part alone.
std::optional<double> maskedPsnr(const cv::Mat& rendered, const cv::Mat& captured,
                                 const cv::Mat& mask);

}  // namespace tessera::eval
