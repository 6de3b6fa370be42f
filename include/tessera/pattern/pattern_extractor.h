#pragma once
// Periodic pattern extraction: a bitmap's lattice from its autocorrelation, then one cell of
// it as a tile, each tile texel the median of all its repetitions in the bitmap (noise
// averages out, an occluding object is outvoted). The tiling must reproduce the bitmap:
// candidate tiles go from the smallest cell to integer multiples of it, and the first whose
// tiling is faithful is kept. Texels the tiling does not explain, in blobs large enough to
// be objects (a poster on a brick wall), are the pattern's overlays.
#include <optional>
#include <string>
#include <vector>

#include <opencv2/core/mat.hpp>
#include <opencv2/core/types.hpp>

#include "tessera/core/lattice2.h"
#include "tessera/pattern/lattice.h"

namespace tessera::pattern {

struct PatternConfig {
  // The autocorrelation runs on the bitmap scaled to at most this many texels a side.
  int analysis_max_px = 256;
  double blur_sigma_px = 1.0;  // of the grey image before the autocorrelation (0: none)
  LatticeConfig lattice;
  // A faithful tiling, over the texels it explains (overlays left out):
  double min_tiling_psnr_db = 20.0;  // ... at least this PSNR (not match.min_psnr_db)
  double min_explained = 0.5;       // ... explains this share of the bitmap's colour variance
  double max_overlay_share = 0.35;  // ... leaves at most this share unexplained
  double min_repeats = 3.0;         // ... from at least this many cells' worth of bitmap
  // A cell of half the area replaces a faithful one when its tiling loses at most this much.
  double finer_psnr_loss_db = 0.5;
  // Unexplained texels: colour error above this many robust noise deviations (and at least
  // min_overlay_error grey levels), in blobs of at least min_overlay_px texels.
  double overlay_sigmas = 4.0;
  double min_overlay_error = 24.0;
  int min_overlay_px = 64;
  // A tile texel is the median of at most this many repetitions, in cells spread evenly over
  // the bitmap (0: all): the median of 32 already has a tenth of the noise of one texel, and
  // a bitmap of small cells would otherwise cost a median over hundreds.
  int max_tile_repetitions = 32;
  // Uneven light (a floor's fall-off, a spotlight): the bitmap is modelled as tile x shading,
  // a smooth gain field estimated over a window of shading_cells cells, and the tiling is
  // built and judged on the bitmap divided by it, when its spread (95th - 5th percentile)
  // reaches min_shading_spread.
  bool shading = true;
  double shading_cells = 0.75;
  double min_shading_spread = 0.05;
};

struct Pattern {
  Periodicity periodicity = Periodicity::kNone;
  // In bitmap texels. The tile is the cell at the bitmap's origin: tile pixel (i, j) is bitmap
  // point (i / W) v1 + (j / H) v2, so the bitmap is the tile rendered through the identity.
  // For stripes v2 runs along them (any length would do).
  core::Lattice2 lattice;
  cv::Mat tile_rgb;                // CV_8UC3, W x H, W ~ |v1| and H ~ cell area / |v1|
  cv::Mat tile_mask;               // CV_8UC1, 255 where some repetition was seen
  double psnr_db = 0.0;            // tiling vs bitmap over the explained texels
  double explained = 0.0;          // 1 - residual / variance over those texels
  double repeats = 0.0;            // valid bitmap area / cell area
  cv::Mat unexplained;             // CV_8UC1 over the bitmap: 255 in an overlay
  std::vector<cv::Rect> overlays;  // bounding boxes of the unexplained blobs
  // CV_32FC1 over the bitmap, mean 1: the bitmap is the tiling times this gain; empty under
  // even light. psnr_db and explained are then those of the bitmap divided by it.
  cv::Mat shading;
  double shading_spread = 0.0;  // its 95th - 5th percentile
};

struct PatternAnalysis {
  LatticeEstimate estimate;        // the autocorrelation's lattice, in bitmap texels
  std::optional<Pattern> pattern;  // the smallest faithful tile, if any
  std::string reason;              // why there is none
  double ms = 0.0;
  Periodicity verdict() const { return pattern ? pattern->periodicity : Periodicity::kNone; }
};

// `rgb` CV_8UC3, `mask` CV_8UC1 (0 = no texel; empty: all valid).
PatternAnalysis analysePattern(const cv::Mat& rgb, const cv::Mat& mask,
                               const PatternConfig& config = {});

// The tile of `lattice`'s cell at the origin, W x H, each texel the per-channel median of the
// bitmap at all its repetitions (bilinear over valid texels); with max_repetitions > 0, at
// the repetitions in that many cells spread evenly over the bitmap.
void averageTile(const cv::Mat& rgb, const cv::Mat& mask, const core::Lattice2& lattice, int width,
                 int height, cv::Mat& tile_rgb, cv::Mat& tile_mask, int max_repetitions = 0);

}  // namespace tessera::pattern
