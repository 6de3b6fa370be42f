#pragma once
// Internal to the pattern module: the tiling of a cell's tile over a bitmap, the inverse of
// averageTile (pattern_extractor.h).
#include <opencv2/core/mat.hpp>

#include "tessera/core/lattice2.h"

namespace tessera::pattern {

// How far the tiling of a cell's tile lies from the bitmap, texel by texel: the tiling is
// match::renderPattern's through the identity (bitmap point q lies at tile pixel (c1 W, c2 H),
// c = L^-1 q wrapped into the cell; its colour is the bilinear mean of the valid tile texels
// around that point, the tile wrapping at its edges).
struct TilingError {
  cv::Mat error;  // CV_32FC1, RMS over the channels of bitmap - tiling; 0 where not compared
  cv::Mat valid;  // CV_8UC1, 255 where compared: a valid bitmap texel whose nearest tile
                  // texel is valid
};
TilingError tilingError(const cv::Mat& rgb, const cv::Mat& mask, const cv::Mat& tile_rgb,
                        const cv::Mat& tile_mask, const core::Lattice2& lattice);

}  // namespace tessera::pattern
