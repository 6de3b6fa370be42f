#pragma once
// Texels from chosen views instead of the mean of all of them. On a real camera two views of a
// surface are registered a few millimetres apart, so their mean smears detail; one view per
// texel keeps it. Following view selection with seam levelling (Lempitsky & Ivanov 2007;
// Waechter et al. 2014), adapted to a patch's texel grid:
//   1. the grid is cut into square regions; each region's candidates are the views with the
//      most summed sample weight there (weight: frontality / distance^2 x frame sharpness, and
//      only where the view saw the plane unoccluded, so coverage counts too);
//   2. each region takes one view, solving data cost + Potts smoothness over the region grid
//      by min-sum belief propagation, so that neighbouring regions come from the same view;
//   3. each view gets a colour gain (least squares over the texels two views share) and each
//      region a smooth colour offset that closes the steps at its seams (global, then local
//      levelling), without touching shading inside a view's area;
//   4. texels near a seam blend the views on either side over seam_texels; a texel its
//      region's view did not see takes the region's next view that did.
// docs/MEASUREMENTS.md, "View selection", has the figures on the real sequences.
#include <cstdint>
#include <vector>

#include <opencv2/core/mat.hpp>

#include "tessera/planes/colour_samples.h"
#include "tessera/texture/texel_grid.h"

namespace tessera::texture {

struct ViewSelectionConfig {
  bool enabled = true;  // false: each texel is the weighted mean of every view
  int region_texels = 16;
  int views_per_region = 3;
  // Potts cost of a seam between two regions, against the data cost log(best / view weight)
  // (capped at 4): 0.25 lets a region keep a view about 1.3 times lighter than its best to
  // avoid one seam.
  double smoothness = 0.25;
  int seam_texels = 3;  // blend width on either side of a seam
  bool level_seams = true;
};

// One region's candidate views, heaviest first, and the labelling's pick.
struct RegionViews {
  std::vector<std::int32_t> views;
  std::vector<double> weights;  // summed sample weight of each view in the region
};

// The view of each region (an index into its candidates; -1 where a region has none), for
// regions on a columns x rows grid (row-major), by min-sum belief propagation over 4-neighbours
// with data cost min(log(best / weight), 4) and Potts cost `smoothness` between different views.
std::vector<int> labelRegions(const std::vector<RegionViews>& regions, int columns, int rows,
                              double smoothness);

// Per-view log gains g_v (per channel) minimising sum n_ab (g_a - g_b - r_ab)^2 + mu sum n_v g_v^2,
// r_ab: the mean log colour ratio of views a and b over n_ab shared texels.
struct ViewPair {
  int a = 0, b = 0;  // indices into the views
  double shared = 0.0;
  cv::Vec3d log_ratio;  // mean log(colour_a / colour_b)
};
std::vector<cv::Vec3d> viewLogGains(int views, const std::vector<ViewPair>& pairs);

// Registration of the views to each other in the patch's plane (the in-plane half of colour
// map optimisation, Zhou & Koltun 2014): each view's samples move by the shift that best
// correlates them (normalised cross-correlation of grey levels, so exposure does not matter)
// with the consensus of all views, found coarse to fine within max_shift_texels, twice over as
// the consensus sharpens. A few millimetres of pose error, or colour taken at another time than
// depth, then no longer puts two views' detail on different texels.
struct ViewAlignmentConfig {
  bool enabled = true;
  double max_shift_texels = 4.0;
  int min_samples = 400;  // views with fewer samples in the patch stay where they are
};

struct ViewShift {
  std::int32_t view = -1;
  double dx = 0.0, dy = 0.0;  // texels, along the grid's x and y axes
};

// Moves the samples of each view by its shift (in place, u and v) and returns the shifts.
std::vector<ViewShift> alignViews(std::vector<planes::ColourSample>& samples, const TexelGrid& grid,
                                  const ViewAlignmentConfig& config);

struct ViewComposite {
  cv::Mat image;     // CV_8UC3 RGB
  cv::Mat observed;  // CV_8U, 255 where a texel got colour
  int regions = 0;
  int views_used = 0;  // distinct views the regions took
  int seams = 0;       // neighbouring region pairs with different views
  // Mean absolute colour step between the two views at the seams (grey levels, mean of the
  // channels), before and after levelling.
  double seam_step = 0.0, seam_step_levelled = 0.0;
};

// The texels of `grid` from `samples` (with views) by view selection. Within a view, a texel
// is the mean of the samples within radius_texels of its centre, weighted by a Gaussian of
// their distance (sigma_texels).
ViewComposite composeByViews(const std::vector<planes::ColourSample>& samples,
                             const TexelGrid& grid, const ViewSelectionConfig& config,
                             double radius_texels, double sigma_texels);

}  // namespace tessera::texture
