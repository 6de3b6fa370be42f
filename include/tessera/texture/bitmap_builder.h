#pragma once
// The initial bitmap of a finalized patch: each texel of its TexelGrid gets the weighted mean
// colour of the nearest colour samples around its centre (the samples binned into buckets of
// the search radius find them). Texels without samples stay uncoloured and masked; small holes
// inside the outline may be inpainted from their surroundings and are marked so.
#include <cstddef>
#include <string>

#include <opencv2/core/mat.hpp>

#include "tessera/core/config.h"
#include "tessera/planes/patch_map.h"
#include "tessera/texture/texel_grid.h"
#include "tessera/texture/view_selection.h"

namespace tessera::texture {

struct BitmapConfig {
  // Texel side, metres. 0: the mean footprint of the pixels that coloured the patch (distance
  // over fx), clamped to [min_texel_m, max_texel_m], so the bitmap is as sharp as the views.
  double texel_m = 0.0;
  double min_texel_m = 0.002;
  double max_texel_m = 0.02;
  // The grid's axes: "principal_axes" of the outline's vertices (the published method) or the
  // "minimum_area" rectangle (about 15 % fewer texels on the office's patches).
  std::string grid = "principal_axes";
  // Each texel averages at most `neighbours` samples within radius_texels of its centre,
  // weighted by each sample's view weight times a Gaussian of its distance (sigma_texels).
  int neighbours = 8;
  double radius_texels = 1.5;
  double sigma_texels = 0.5;
  // Instead of averaging, take the colour of the one sample with the best view weight.
  bool best_view = false;
  // Texels from views chosen per region (view_selection.h), where the samples keep their views
  // apart (patches: sample_views > 0); otherwise the mean or best view above.
  ViewSelectionConfig views;
  // Each view's samples shifted in the plane to agree with the others first (any rule above).
  ViewAlignmentConfig alignment;
  // Holes inside the outline of at most this many texels, ringed by coloured texels, are
  // inpainted (0: none).
  int max_inpaint_texels = 16;
};

// Reads the `textures:` keys; throws core::ConfigError on a value out of range.
void readConfig(const core::ConfigSection& section, BitmapConfig& config);

// What each texel of a bitmap holds.
enum class TexelState : std::uint8_t {
  kEmpty = 0,        // outside the outline, or no sample near it
  kInpainted = 128,  // a small hole filled from its neighbours
  kObserved = 255,   // the mean of observed samples
};

struct PatchBitmap {
  int id = 0;
  int version = 0;
  TexelGrid grid;  // grid.mask: the outline
  cv::Mat image;   // CV_8UC3 RGB, black where empty
  cv::Mat state;   // CV_8UC1 TexelState
  std::size_t observed = 0, inpainted = 0;
  double build_ms = 0.0;
  // View selection: distinct views used, seams between regions of different views, and the
  // mean colour step at the seams as sampled and after levelling (grey levels).
  int views_used = 0, seams = 0;
  double seam_step = 0.0, seam_step_levelled = 0.0;
  // View alignment: views moved, and how far (millimetres in the plane).
  int views_moved = 0;
  double view_shift_mean_mm = 0.0, view_shift_max_mm = 0.0;
  double area_m2() const { return static_cast<double>(observed) * grid.texel_m * grid.texel_m; }
};

// The texel size for a patch under `config`.
double texelSizeFor(const planes::PatchSnapshot& patch, const BitmapConfig& config);

// Builds the bitmap of one patch. Thread-safe: patches are built in parallel.
PatchBitmap buildBitmap(const planes::PatchSnapshot& patch, const BitmapConfig& config);

// The same bitmap by brute force over every sample (no tree, no inpainting): the slow
// reference the tests hold buildBitmap to.
PatchBitmap buildBitmapBruteForce(const planes::PatchSnapshot& patch, const BitmapConfig& config);

}  // namespace tessera::texture
