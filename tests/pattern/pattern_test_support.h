#pragma once
// Images with a known period lattice for the pattern tests: a smooth random tile (seeded)
// repeated over the plane by core::Lattice2, rendered through match::renderPattern.
#include <cstdint>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "tessera/core/lattice2.h"
#include "tessera/match/fidelity.h"

namespace tessera::pattern::testing {

// A W x H RGB tile of smoothed random colour blobs, wrapping smoothly at its edges.
inline cv::Mat randomTile(int width, int height, std::uint64_t seed) {
  cv::RNG rng(seed);
  cv::Mat noise(height, width, CV_32FC3);
  rng.fill(noise, cv::RNG::UNIFORM, 0.0, 255.0);
  cv::Mat big;  // blurred over a 3 x 3 repeat so that the tile's edges wrap
  cv::repeat(noise, 3, 3, big);
  cv::GaussianBlur(big, big, cv::Size(), 1.5);
  cv::Mat tile = big(cv::Rect(width, height, width, height)).clone();
  cv::normalize(tile, tile, 20, 235, cv::NORM_MINMAX);
  tile.convertTo(tile, CV_8UC3);
  return tile;
}

// The plane tiled by `lattice` (the tile is its cell), seen through `patch_to_frame`.
inline cv::Mat tiling(const cv::Mat& tile, const core::Lattice2& lattice, int width, int height,
                      const core::Similarity2& patch_to_frame = {}) {
  return match::renderPattern(tile, {}, lattice, patch_to_frame, width, height).rgb;
}

}  // namespace tessera::pattern::testing
