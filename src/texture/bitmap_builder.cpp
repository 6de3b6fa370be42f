#include "tessera/texture/bitmap_builder.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <numeric>
#include <vector>

#include <opencv2/imgproc.hpp>
#include <opencv2/photo.hpp>

#include "internal/sample_buckets.h"
#include "tessera/core/error.h"

namespace tessera::texture {

namespace {

using planes::ColourSample;

constexpr std::size_t kMaxTexels = 64'000'000;  // 192 MB of RGB

// The colour of one texel from its neighbouring samples (indices into `samples`, with squared
// distances to the texel centre): the view weights exp(score) relative to the best of them,
// times a Gaussian of the distance; or the single heaviest sample in best-view mode.
cv::Vec3b texelColour(const std::vector<ColourSample>& samples, const std::vector<int>& indices,
                      const std::vector<double>& distance2, double two_sigma2, bool best_view) {
  // Log weights: view score plus the Gaussian's exponent; relative to the largest, so the
  // heaviest sample weighs 1 and the sum cannot underflow to zero.
  double best_log = -std::numeric_limits<double>::infinity();
  for (std::size_t j = 0; j < indices.size(); ++j) {
    best_log = std::max(best_log,
                        static_cast<double>(samples[indices[j]].score) - distance2[j] / two_sigma2);
  }
  double sum[3] = {0.0, 0.0, 0.0}, total = 0.0, heaviest = -1.0;
  cv::Vec3b best;
  for (std::size_t j = 0; j < indices.size(); ++j) {
    const ColourSample& s = samples[indices[j]];
    const double w = std::exp(static_cast<double>(s.score) - distance2[j] / two_sigma2 - best_log);
    if (w > heaviest) heaviest = w, best = cv::Vec3b(s.rgb[0], s.rgb[1], s.rgb[2]);
    for (int c = 0; c < 3; ++c) sum[c] += w * s.rgb[c];
    total += w;
  }
  if (best_view) return best;
  return {cv::saturate_cast<std::uint8_t>(sum[0] / total),
          cv::saturate_cast<std::uint8_t>(sum[1] / total),
          cv::saturate_cast<std::uint8_t>(sum[2] / total)};
}

PatchBitmap emptyBitmap(const planes::PatchSnapshot& patch, const BitmapConfig& config) {
  PatchBitmap bitmap;
  bitmap.id = patch.id;
  bitmap.version = patch.version;
  double t = texelSizeFor(patch, config);
  // A grid beyond kMaxTexels (a huge patch at a fine texel) gets coarser texels instead; the
  // sizes come from the outline's vertices alone, before any image is allocated.
  const GridSizes sizes = compareGrids(patch.outline, t);
  const std::size_t texels =
      config.grid == "minimum_area" ? sizes.minimum_area : sizes.principal_axes;
  if (texels > kMaxTexels) {
    t *= 1.01 * std::sqrt(static_cast<double>(texels) / static_cast<double>(kMaxTexels));
  }
  bitmap.grid = config.grid == "minimum_area" ? minimumAreaGrid(patch.outline, t)
                                              : principalAxisGrid(patch.outline, t);
  bitmap.image = cv::Mat::zeros(bitmap.grid.height, bitmap.grid.width, CV_8UC3);
  bitmap.state = cv::Mat::zeros(bitmap.grid.height, bitmap.grid.width, CV_8UC1);
  return bitmap;
}

// Visits the centre (in (u, v)) of every texel inside the outline.
template <typename Visit>
void forEachTexel(const TexelGrid& grid, Visit visit) {
  for (int r = 0; r < grid.height; ++r) {
    const auto* inside = grid.mask.ptr<std::uint8_t>(r);
    for (int c = 0; c < grid.width; ++c) {
      if (inside[c] != 0) visit(r, c, grid.uvOf(c + 0.5, r + 0.5));
    }
  }
}

void setObserved(PatchBitmap& bitmap, int r, int c, const cv::Vec3b& colour) {
  bitmap.image.at<cv::Vec3b>(r, c) = colour;
  bitmap.state.at<std::uint8_t>(r, c) = static_cast<std::uint8_t>(TexelState::kObserved);
  ++bitmap.observed;
}

// Fills the holes inside the outline that are at most max_texels large and ringed by observed
// texels only (a hole touching the outline's edge or an unobserved area has nothing reliable
// on one side).
void inpaintSmallHoles(PatchBitmap& bitmap, int max_texels) {
  cv::Mat holes = bitmap.grid.mask & (bitmap.state == 0);
  cv::Mat labels, stats, centroids;
  const int count = cv::connectedComponentsWithStats(holes, labels, stats, centroids, 4);
  cv::Mat fill = cv::Mat::zeros(holes.size(), CV_8UC1);
  const cv::Mat observed = bitmap.state == static_cast<int>(TexelState::kObserved);
  const cv::Mat cross = cv::getStructuringElement(cv::MORPH_CROSS, cv::Size(3, 3));
  for (int label = 1; label < count; ++label) {
    if (stats.at<int>(label, cv::CC_STAT_AREA) > max_texels) continue;
    const cv::Rect box(
        stats.at<int>(label, cv::CC_STAT_LEFT) - 1, stats.at<int>(label, cv::CC_STAT_TOP) - 1,
        stats.at<int>(label, cv::CC_STAT_WIDTH) + 2, stats.at<int>(label, cv::CC_STAT_HEIGHT) + 2);
    const cv::Rect inside = box & cv::Rect(0, 0, holes.cols, holes.rows);
    if (inside != box) continue;  // touches the bitmap's border
    const cv::Mat component = labels(box) == label;
    cv::Mat ring;
    cv::dilate(component, ring, cross);
    ring &= ~component;
    if (cv::countNonZero(ring & ~observed(box)) > 0) continue;
    fill(box) |= component;
  }
  const int filled = cv::countNonZero(fill);
  if (filled == 0) return;
  // Radius 1: only the observed ring around each hole is known to be good colour.
  cv::inpaint(bitmap.image, fill, bitmap.image, 1.0, cv::INPAINT_TELEA);
  bitmap.state.setTo(static_cast<int>(TexelState::kInpainted), fill);
  bitmap.inpainted = static_cast<std::size_t>(filled);
}

}  // namespace

void readConfig(const core::ConfigSection& section, BitmapConfig& config) {
  section.read("texel_m", config.texel_m);
  section.read("min_texel_m", config.min_texel_m);
  section.read("max_texel_m", config.max_texel_m);
  section.read("grid", config.grid);
  section.read("neighbours", config.neighbours);
  section.read("radius_texels", config.radius_texels);
  section.read("sigma_texels", config.sigma_texels);
  section.read("best_view", config.best_view);
  section.read("max_inpaint_texels", config.max_inpaint_texels);
  section.read("view_selection", config.views.enabled);
  section.read("region_texels", config.views.region_texels);
  section.read("views_per_region", config.views.views_per_region);
  section.read("seam_smoothness", config.views.smoothness);
  section.read("seam_texels", config.views.seam_texels);
  section.read("level_seams", config.views.level_seams);
  section.read("align_views", config.alignment.enabled);
  section.read("max_view_shift_texels", config.alignment.max_shift_texels);
  if (config.views.region_texels < 4 || config.views.views_per_region < 1 ||
      config.views.smoothness < 0.0 || config.views.seam_texels < 1 ||
      config.views.seam_texels > config.views.region_texels / 2 ||
      config.alignment.max_shift_texels <= 0.0) {
    throw core::ConfigError(
        "textures: region_texels must be at least 4, views_per_region and seam_texels at least "
        "1, seam_texels at most half of region_texels, seam_smoothness at least 0, "
        "max_view_shift_texels positive");
  }
  constexpr double kFinest = 0.0005;  // half a millimetre: finer than any depth camera sees
  if ((config.texel_m != 0.0 && config.texel_m < kFinest) || config.min_texel_m < kFinest ||
      config.max_texel_m < config.min_texel_m) {
    throw core::ConfigError(
        "textures: texel_m must be 0 (automatic) or at least 0.0005, min_texel_m at least "
        "0.0005 and max_texel_m at least min_texel_m");
  }
  if (config.grid != "principal_axes" && config.grid != "minimum_area") {
    throw core::ConfigError("textures: grid must be principal_axes or minimum_area, not " +
                            config.grid);
  }
  if (config.neighbours < 1 || config.radius_texels <= 0.0 || config.sigma_texels <= 0.0 ||
      config.max_inpaint_texels < 0) {
    throw core::ConfigError(
        "textures: neighbours must be at least 1, radius_texels and sigma_texels positive, "
        "max_inpaint_texels at least 0");
  }
}

double texelSizeFor(const planes::PatchSnapshot& patch, const BitmapConfig& config) {
  if (config.texel_m > 0.0) return config.texel_m;
  const double footprint = patch.pixel_footprint_m > 0.0 ? patch.pixel_footprint_m : 0.005;
  return std::clamp(footprint, config.min_texel_m, config.max_texel_m);
}

PatchBitmap buildBitmap(const planes::PatchSnapshot& patch, const BitmapConfig& config) {
  const auto start = std::chrono::steady_clock::now();
  PatchBitmap bitmap = emptyBitmap(patch, config);
  // Samples the map shares are listed now, on this thread; a given list is read where it is.
  std::vector<ColourSample> listed;
  if (patch.shared_samples) listed = planes::sampleList(patch);
  const std::vector<ColourSample>& given = patch.shared_samples ? listed : patch.samples;
  const bool views_apart = std::any_of(given.begin(), given.end(),
                                       [](const ColourSample& s) { return s.view >= 0; });
  // Views kept apart are aligned to each other, which moves their samples: a copy of a given
  // list. Blended samples (the default) have no views to align and are read where they are.
  std::vector<ColourSample> aligned;
  if (views_apart) {
    if (patch.shared_samples) {
      aligned = std::move(listed);
    } else {
      aligned = patch.samples;
    }
    const std::vector<ViewShift> shifts = alignViews(aligned, bitmap.grid, config.alignment);
    for (const ViewShift& shift : shifts) {
      const double mm = 1000.0 * bitmap.grid.texel_m * std::hypot(shift.dx, shift.dy);
      bitmap.view_shift_mean_mm += mm / static_cast<double>(shifts.size());
      bitmap.view_shift_max_mm = std::max(bitmap.view_shift_max_mm, mm);
    }
    bitmap.views_moved = static_cast<int>(shifts.size());
  }
  const std::vector<ColourSample>& samples = views_apart ? aligned : given;
  if (config.views.enabled && views_apart) {
    const ViewComposite composite = composeByViews(samples, bitmap.grid, config.views,
                                                   config.radius_texels, config.sigma_texels);
    bitmap.image = composite.image;
    bitmap.state.setTo(static_cast<int>(TexelState::kObserved), composite.observed);
    bitmap.observed = static_cast<std::size_t>(cv::countNonZero(composite.observed));
    bitmap.views_used = composite.views_used;
    bitmap.seams = composite.seams;
    bitmap.seam_step = composite.seam_step;
    bitmap.seam_step_levelled = composite.seam_step_levelled;
  } else if (!samples.empty()) {
    const TexelGrid& grid = bitmap.grid;
    const double t = grid.texel_m;
    const double radius = config.radius_texels * t;
    const double two_sigma2 = 2.0 * std::pow(config.sigma_texels * t, 2);
    // The rectangle of (u, v) the texel centres lie in.
    Eigen::Vector2d low = grid.origin_uv, high = grid.origin_uv;
    for (const Eigen::Vector2d& corner : {grid.uvOf(grid.width, 0), grid.uvOf(0, grid.height),
                                          grid.uvOf(grid.width, grid.height)}) {
      low = low.cwiseMin(corner);
      high = high.cwiseMax(corner);
    }
    SampleBuckets buckets(samples, radius, low, high);
    std::vector<int> indices;
    std::vector<double> distance2;
    forEachTexel(grid, [&](int r, int c, const Eigen::Vector2d& uv) {
      if (buckets.nearest(uv, config.neighbours, indices, distance2) <= 0) return;
      setObserved(bitmap, r, c,
                  texelColour(samples, indices, distance2, two_sigma2, config.best_view));
    });
  }
  if (config.max_inpaint_texels > 0) inpaintSmallHoles(bitmap, config.max_inpaint_texels);
  bitmap.build_ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  return bitmap;
}

PatchBitmap buildBitmapBruteForce(const planes::PatchSnapshot& patch, const BitmapConfig& config) {
  PatchBitmap bitmap = emptyBitmap(patch, config);
  const std::vector<ColourSample> samples = planes::sampleList(patch);
  const double t = bitmap.grid.texel_m;
  const double radius2 = std::pow(config.radius_texels * t, 2);
  const double two_sigma2 = 2.0 * std::pow(config.sigma_texels * t, 2);
  std::vector<int> order(samples.size());
  forEachTexel(bitmap.grid, [&](int r, int c, const Eigen::Vector2d& uv) {
    std::vector<double> all(samples.size());
    for (std::size_t i = 0; i < samples.size(); ++i) {
      all[i] = (Eigen::Vector2d(samples[i].u, samples[i].v) - uv).squaredNorm();
    }
    std::iota(order.begin(), order.end(), 0);
    std::sort(order.begin(), order.end(), [&](int a, int b) { return all[a] < all[b]; });
    std::vector<int> indices;
    std::vector<double> distance2;
    for (int i : order) {
      if (all[i] > radius2 || static_cast<int>(indices.size()) == config.neighbours) break;
      indices.push_back(i);
      distance2.push_back(all[i]);
    }
    if (indices.empty()) return;
    setObserved(bitmap, r, c,
                texelColour(samples, indices, distance2, two_sigma2, config.best_view));
  });
  return bitmap;
}

}  // namespace tessera::texture
