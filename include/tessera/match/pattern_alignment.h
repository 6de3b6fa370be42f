#pragma once
// A new pattern against a stored one when their texel grids are turned by a few degrees (two
// walls of the same bricks, each grid aligned with its own patch): cross-correlation at
// quarter turns cannot follow that, but the two lattices give the turn and scale directly,
// and a search over one stored cell gives the phase.
#include <optional>

#include <opencv2/core/mat.hpp>

#include "tessera/core/lattice2.h"
#include "tessera/core/similarity2.h"
#include "tessera/match/match_cascade.h"

namespace tessera::match {

struct PatternAlignmentConfig {
  // The linear map taking one reduced lattice basis onto the other must be a similarity
  // within this relative error (else the lattices differ in shape: another pattern).
  double max_shape_error = 0.04;
  double min_scale = 0.5, max_scale = 2.0;  // of the stored frame against the new texels
};

// The similarity new texel -> stored texture frame under which `lattice` (the new pattern's,
// in texels) lands on the stored pattern's lattice and the new tile's colours (CV_8UC3, one
// cell of `lattice` as core::Lattice2 describes) best match the stored tile's; nothing when
// `stored` is not a pattern or no pairing of the two bases is a similarity.
std::optional<core::Similarity2> alignPattern(const cv::Mat& tile_rgb, const cv::Mat& tile_mask,
                                              const core::Lattice2& lattice,
                                              const StoredTexture& stored,
                                              const PatternAlignmentConfig& config = {});

// `initial` (bitmap texel -> stored frame) refined on the bitmap itself (CV_8UC3 with its
// CV_8UC1 mask): turn, scale and phase by a compass search on the colour difference over a
// sparse grid of texels, so that a lattice estimated a tenth of a texel off does not drift
// by texels across a wall.
core::Similarity2 refineAlignment(const cv::Mat& rgb, const cv::Mat& mask,
                                  const StoredTexture& stored, const core::Similarity2& initial);

}  // namespace tessera::match
