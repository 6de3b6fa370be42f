#pragma once
// Objects on a surface that a rendering of it does not explain (a poster on a brick wall, a
// blackboard on a plaster wall that another wall's texture shows bare): blobs of texels whose
// colour error stands out from the render's own noise.
#include <vector>

#include <opencv2/core/mat.hpp>
#include <opencv2/core/types.hpp>

namespace tessera::pattern {

struct OverlayConfig {
  // Unexplained: error (averaged over 7 x 7 texels) above this many robust deviations of the
  // error (1.4826 x its median) and at least min_error grey levels, in blobs of at least
  // min_px texels.
  double sigmas = 4.0;
  double min_error = 24.0;
  int min_px = 64;
};

struct Overlays {
  cv::Mat unexplained;             // CV_8UC1: 255 in a blob (holes filled, grown 2 texels)
  std::vector<cv::Rect> blobs;     // bounding boxes, largest first
  double unexplained_share = 0.0;  // of the compared texels
};

// `error`: CV_32FC1, the per-texel RMS colour difference between a bitmap and its render;
// `compared`: CV_8UC1, 255 where it counts.
Overlays findOverlays(const cv::Mat& error, const cv::Mat& compared, const OverlayConfig& config);

// The per-texel RMS over the channels of a - b (CV_8UC3 each), CV_32FC1.
cv::Mat colourError(const cv::Mat& a, const cv::Mat& b);

}  // namespace tessera::pattern
