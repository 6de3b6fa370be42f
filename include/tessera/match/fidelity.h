#pragma once
// What a reuse costs: a stored texture rendered through a similarity onto a patch's texel grid
// and compared with the patch's own bitmap over its mask (PSNR on 8-bit RGB).
#include <cstddef>

#include <opencv2/core/mat.hpp>

#include "tessera/core/lattice2.h"
#include "tessera/core/similarity2.h"

namespace tessera::match {

// `texture` (CV_8UC3) seen through `patch_to_texture` (patch texel centre (col, row) -> texture
// pixel coordinates, bilinear) on a width x height grid. `tiled`: the texture repeats (a pattern
// tile), else texels that map outside it, or onto its masked-out pixels (`texture_mask`, CV_8UC1,
// 0 = none; empty: all valid), are left out of `covered`.
struct Rendered {
  cv::Mat rgb;      // CV_8UC3
  cv::Mat covered;  // CV_8UC1, 255 where the texture gave a colour
};
Rendered renderThrough(const cv::Mat& texture, const cv::Mat& texture_mask,
                       const core::Similarity2& patch_to_texture, int width, int height,
                       bool tiled);

// A pattern: `tile` (CV_8UC3, with `tile_mask` as above) is one cell of `lattice` in the
// texture frame (core::Lattice2), repeated over the whole plane; `patch_to_frame` maps patch
// texel centres into that frame. With lattice (W, 0), (0, H) this is renderThrough, tiled.
Rendered renderPattern(const cv::Mat& tile, const cv::Mat& tile_mask, const core::Lattice2& lattice,
                       const core::Similarity2& patch_to_frame, int width, int height);

// The PSNR of identical pixels (a finite stand-in for infinity).
inline constexpr double kIdenticalPsnrDb = 99.0;

struct Fidelity {
  double psnr_db = 0.0;    // over the patch mask texels the texture covers (99 when identical)
  double coverage = 0.0;   // covered mask texels / mask texels
  std::size_t texels = 0;  // mask texels compared
};

// PSNR of a render against `patch_rgb` (CV_8UC3) over `patch_mask` (CV_8UC1).
Fidelity measureFidelity(const cv::Mat& patch_rgb, const cv::Mat& patch_mask,
                         const Rendered& rendered);

// The same for `texture` rendered through `patch_to_texture` (see renderThrough).
Fidelity measureFidelity(const cv::Mat& patch_rgb, const cv::Mat& patch_mask,
                         const cv::Mat& texture, const cv::Mat& texture_mask,
                         const core::Similarity2& patch_to_texture, bool tiled);

}  // namespace tessera::match
