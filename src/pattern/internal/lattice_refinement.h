#pragma once
// Lattice vectors refined on the full-size bitmap: the autocorrelation runs on a scaled copy,
// whose texels are up to several bitmap texels wide, and a tile averaged over 20 repeats of a
// vector half a texel off is blurred by 10 texels at the far end.
#include <opencv2/core/mat.hpp>

#include "tessera/core/lattice2.h"

namespace tessera::pattern {

// Each of `vectors` (1: v1 only, for stripes; 2: both) refined through its multiples k v
// (k = 2, 4, 8 while k v fits in half the bitmap): the shift near k v where the blurred colours
// repeat best (compass search down to 1/8 texel), divided by k.
core::Lattice2 refineLattice(const cv::Mat& rgb, const cv::Mat& mask, core::Lattice2 lattice,
                             int vectors);

}  // namespace tessera::pattern
