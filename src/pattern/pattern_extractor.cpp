#include "tessera/pattern/pattern_extractor.h"
#include "tessera/pattern/overlays.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdint>

#include <fmt/format.h>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "internal/lattice_refinement.h"
#include "internal/shading.h"
#include "internal/tiling.h"
#include "tessera/core/error.h"
#include "tessera/match/fidelity.h"

namespace tessera::pattern {

namespace {

// Texel size of the stored cell: about one bitmap texel per tile pixel.
cv::Size tileSize(const core::Lattice2& lattice) {
  const double w = std::max(1.0, std::round(lattice.v1.norm()));
  const double h = std::max(1.0, std::round(lattice.cellArea() / lattice.v1.norm()));
  return {static_cast<int>(w), static_cast<int>(h)};
}

struct Faithfulness {
  double psnr_db = 0.0, explained = 0.0, unexplained_share = 1.0;
  cv::Mat unexplained;
  std::vector<cv::Rect> overlays;
};

// How well the tiling reproduces the bitmap, and which blobs it leaves unexplained.
Faithfulness judgeTiling(const cv::Mat& rgb, const TilingError& tiling,
                         const PatternConfig& config) {
  Faithfulness out;
  const cv::Mat& error = tiling.error;
  const cv::Mat& valid = tiling.valid;
  Overlays overlays = findOverlays(
      error, valid, {config.overlay_sigmas, config.min_overlay_error, config.min_overlay_px});
  out.unexplained = std::move(overlays.unexplained);
  out.overlays = std::move(overlays.blobs);
  out.unexplained_share = overlays.unexplained_share;

  // PSNR and explained variance over the texels the tiling explains: sums of the squared
  // residual (3 e^2 a texel) and of each channel and its square.
  double n = 0.0, sse = 0.0;
  std::array<double, 3> sum{}, sum2{};
  for (int row = 0; row < rgb.rows; ++row) {
    const auto* p = rgb.ptr<cv::Vec3b>(row);
    const auto* e = error.ptr<float>(row);
    const auto* v = valid.ptr<std::uint8_t>(row);
    const auto* u = out.unexplained.ptr<std::uint8_t>(row);
    for (int col = 0; col < rgb.cols; ++col) {
      if (v[col] == 0 || u[col] != 0) continue;
      n += 1.0;
      sse += 3.0 * static_cast<double>(e[col]) * e[col];
      for (int c = 0; c < 3; ++c) {
        const double x = p[col][c];
        sum[static_cast<std::size_t>(c)] += x;
        sum2[static_cast<std::size_t>(c)] += x * x;
      }
    }
  }
  if (n < 1.0) return out;
  double sst = 0.0;
  for (std::size_t c = 0; c < 3; ++c) sst += sum2[c] - sum[c] * sum[c] / n;
  const double mse = sse / (3.0 * n);
  out.psnr_db = mse > 0.0 ? std::min(99.0, 10.0 * std::log10(255.0 * 255.0 / mse)) : 99.0;
  out.explained = sst > 0.0 ? 1.0 - sse / sst : 0.0;
  return out;
}

// The grey image with its local mean removed and its local contrast made one (normalised
// convolution over the mask, a wide blur of `sigma`): a bright occluder or a lighting gradient
// would otherwise dominate the autocorrelation with its own broad bump.
cv::Mat locallyNormalised(const cv::Mat& grey, const cv::Mat& mask, double sigma) {
  cv::Mat m;
  cv::Mat den;
  if (!mask.empty()) {
    cv::Mat(mask != 0).convertTo(m, CV_32F, 1.0 / 255.0);
    den = cv::max(wideBlur(m, sigma), 1e-3);
  }
  const auto masked_blur = [&m, &den, sigma](const cv::Mat& image) {
    if (m.empty()) return wideBlur(image, sigma);
    return cv::Mat(wideBlur(image.mul(m), sigma) / den);
  };
  const cv::Mat centred = grey - masked_blur(grey);
  cv::Mat deviation;
  cv::sqrt(masked_blur(centred.mul(centred)), deviation);
  // 2 grey levels of floor: a plain region stays low instead of becoming amplified noise.
  cv::Mat out = centred / (deviation + 2.0f);
  if (!m.empty()) out = out.mul(m);
  return out;
}

// The bitmap scaled to at most analysis_max_px a side (INTER_AREA), where the lattice is
// found and the candidate tiles are compared; a scaled texel is valid when all of it is.
struct Scaled {
  cv::Mat rgb, mask;
  double f = 1.0;  // scaled texels per bitmap texel
};

Scaled scaledForAnalysis(const cv::Mat& rgb, const cv::Mat& mask, const PatternConfig& config) {
  Scaled out{rgb, mask, 1.0};
  const int longest = std::max(rgb.cols, rgb.rows);
  if (config.analysis_max_px <= 0 || longest <= config.analysis_max_px) return out;
  out.f = static_cast<double>(config.analysis_max_px) / longest;
  cv::resize(rgb, out.rgb, cv::Size(), out.f, out.f, cv::INTER_AREA);
  if (!mask.empty()) {
    cv::resize(mask, out.mask, out.rgb.size(), 0, 0, cv::INTER_AREA);
    out.mask = out.mask >= 255;
  }
  return out;
}

namespace {

// Bilinear sampling at a fixed sub-texel offset o: the four neighbours at floor(o) and weights
// that are the same for every texel.
struct FixedShift {
  int ox = 0, oy = 0;
  std::array<float, 4> w{};
  explicit FixedShift(const Eigen::Vector2d& o) {
    const double x0 = std::floor(o.x()), y0 = std::floor(o.y());
    ox = static_cast<int>(x0);
    oy = static_cast<int>(y0);
    const auto fx = static_cast<float>(o.x() - x0), fy = static_cast<float>(o.y() - y0);
    w = {(1 - fx) * (1 - fy), fx * (1 - fy), (1 - fx) * fy, fx * fy};
  }
  // The colour at (row, col) + o, when its four neighbours are valid.
  bool sample(const cv::Mat& rgb, const cv::Mat& mask, int row, int col,
              std::array<float, 3>& colour) const {
    const int y = row + oy, x = col + ox;
    if (!mask.empty() &&
        (mask.at<std::uint8_t>(y, x) == 0 || mask.at<std::uint8_t>(y, x + 1) == 0 ||
         mask.at<std::uint8_t>(y + 1, x) == 0 || mask.at<std::uint8_t>(y + 1, x + 1) == 0)) {
      return false;
    }
    const auto* top = rgb.ptr<cv::Vec3b>(y) + x;
    const auto* bottom = rgb.ptr<cv::Vec3b>(y + 1) + x;
    for (int c = 0; c < 3; ++c) {
      colour[static_cast<std::size_t>(c)] =
          w[0] * top[0][c] + w[1] * top[1][c] + w[2] * bottom[0][c] + w[3] * bottom[1][c];
    }
    return true;
  }
};

}  // namespace

// The repeat cost of shift d (see RepeatCost), over valid pairs centred on every third row
// and column; nothing when too few pairs exist. The pair is x - d/2 and x + d/2, so that both
// samples are interpolated by the same fraction of a texel: a shift between texels is not
// judged worse for being smoothed.
std::optional<RepeatCost> repeatError(const cv::Mat& rgb, const cv::Mat& mask,
                                      const Eigen::Vector2d& d) {
  const FixedShift back(-0.5 * d), ahead(0.5 * d);
  // Rows and columns where both samples' neighbours lie inside the bitmap.
  const int row0 = std::max({0, -back.oy, -ahead.oy});
  const int row1 = std::min({rgb.rows, rgb.rows - back.oy - 1, rgb.rows - ahead.oy - 1});
  const int col0 = std::max({0, -back.ox, -ahead.ox});
  const int col1 = std::min({rgb.cols, rgb.cols - back.ox - 1, rgb.cols - ahead.ox - 1});
  std::vector<float> errors;
  errors.reserve(rgb.total() / 9 + 1);
  std::array<float, 3> a{}, b{};
  std::array<double, 3> colour_sum{}, colour_squares{};
  for (int row = row0 + (3 - row0 % 3) % 3; row < row1; row += 3) {
    for (int col = col0 + (3 - col0 % 3) % 3; col < col1; col += 3) {
      if (!back.sample(rgb, mask, row, col, a) || !ahead.sample(rgb, mask, row, col, b)) continue;
      float sum = 0.0f;
      for (std::size_t c = 0; c < 3; ++c) {
        sum += (b[c] - a[c]) * (b[c] - a[c]);
        colour_sum[c] += a[c];
        colour_squares[c] += a[c] * a[c];
      }
      errors.push_back(sum);
    }
  }
  if (errors.size() < 64) return std::nullopt;
  RepeatCost cost;
  const auto n = static_cast<double>(errors.size());
  for (std::size_t c = 0; c < 3; ++c) {
    const double mean = colour_sum[c] / n;
    cost.unrelated += 2.0 * (colour_squares[c] / n - mean * mean);
  }
  double total = 0.0;
  for (const float e : errors) total += e;
  cost.mean = total / static_cast<double>(errors.size());
  const auto kept = errors.begin() + static_cast<long>(0.6 * static_cast<double>(errors.size()));
  std::nth_element(errors.begin(), kept, errors.end());
  double lower = 0.0;
  for (auto it = errors.begin(); it != kept; ++it) lower += *it;
  cost.trimmed = lower / static_cast<double>(std::max<long>(1, kept - errors.begin()));
  return cost;
}

LatticeEstimate estimateOn(const Scaled& scaled, const PatternConfig& config) {
  cv::Mat grey;
  cv::cvtColor(scaled.rgb, grey, cv::COLOR_RGB2GRAY);
  grey.convertTo(grey, CV_32F);
  if (config.blur_sigma_px > 0.0) {
    cv::GaussianBlur(grey, grey, cv::Size(), config.blur_sigma_px);
  }
  grey = locallyNormalised(grey, scaled.mask, std::max(8.0, std::max(grey.cols, grey.rows) / 8.0));
  // Colours compared blurred a little, so that a shift between texels (whose bilinear
  // samples are smoother than the texels) is not judged worse than a whole-texel one.
  cv::Mat smooth_rgb;
  cv::GaussianBlur(scaled.rgb, smooth_rgb, cv::Size(), 1.0);
  const RepeatError colour_error = [&smooth_rgb, &scaled](const Eigen::Vector2d& d) {
    return repeatError(smooth_rgb, scaled.mask, d);
  };
  return estimateLattice(autocorrelate(grey, scaled.mask), config.lattice, colour_error);
}

// The lattices of index 2 above `l` (for stripes: twice the period).
std::vector<core::Lattice2> coarserLattices(const core::Lattice2& l, bool stripes) {
  if (stripes) return {{2.0 * l.v1, l.v2}};
  return {reduceBasis({2.0 * l.v1, l.v2}), reduceBasis({l.v1, 2.0 * l.v2}),
          reduceBasis({l.v1 + l.v2, l.v1 - l.v2})};
}

// Tiles to try, smallest first: the cell, then the coarser lattices above it.
std::vector<core::Lattice2> candidateCells(const core::Lattice2& cell, bool stripes) {
  std::vector<core::Lattice2> cells{cell};
  for (const core::Lattice2& coarser : coarserLattices(cell, stripes)) cells.push_back(coarser);
  if (!stripes) cells.push_back({2.0 * cell.v1, 2.0 * cell.v2});
  return cells;
}

// The tiling of a cell's tile over the bitmap's extent, and where it gives a colour.
match::Rendered tiledOver(const cv::Mat& rgb, const cv::Mat& tile_rgb, const cv::Mat& tile_mask,
                          const core::Lattice2& cell) {
  return match::renderPattern(tile_rgb, tile_mask, cell, {}, rgb.cols, rgb.rows);
}

// The bitmap's shading under the cell's tiling (pattern.shading, internal/shading.h), when the
// light varies by at least config.min_shading_spread; empty under even light. The tile and
// the field are estimated in turn: the tile from the bitmap divided by the field, the field
// from the bitmap against the tile's tiling. The light does not depend on which multiple of
// the cell is tried, so one fit serves every candidate.
cv::Mat shadingOf(const cv::Mat& rgb, const cv::Mat& mask, const core::Lattice2& cell,
                  const PatternConfig& config) {
  if (!config.shading) return {};
  const cv::Size size = tileSize(cell);
  cv::Mat tile_rgb, tile_mask;
  averageTile(rgb, mask, cell, size.width, size.height, tile_rgb, tile_mask,
              config.max_tile_repetitions);
  const double sigma =
      std::max(4.0, config.shading_cells * std::max(cell.v1.norm(), cell.v2.norm()));
  cv::Mat gain;
  for (int round = 0; round < 3; ++round) {
    const match::Rendered tiled = tiledOver(rgb, tile_rgb, tile_mask, cell);
    const cv::Mat valid = mask.empty() ? tiled.covered : (tiled.covered & mask);
    gain = estimateShading(rgb, tiled.rgb, valid, sigma);
    // Fitted again without what the tiling does not explain (an occluder would pull it).
    const cv::Mat explained = explainedByShading(rgb, tiled.rgb, gain, valid);
    gain = estimateShading(rgb, tiled.rgb, explained, sigma);
    if (round == 0 && shadingSpread(gain, explained) < config.min_shading_spread) return {};
    averageTile(unshaded(rgb, gain), mask, cell, size.width, size.height, tile_rgb, tile_mask,
                config.max_tile_repetitions);
  }
  return gain;
}

// The cell's tile built from `rgb` and judged against it; under uneven light (a `shading`,
// resized to the bitmap if fitted on the scaled one), from and against the bitmap divided by
// it.
Pattern tileAndJudge(const cv::Mat& rgb, const cv::Mat& mask, const core::Lattice2& cell,
                     Periodicity periodicity, const PatternConfig& config, const cv::Mat& shading,
                     double& unexplained_share) {
  Pattern pattern;
  pattern.periodicity = periodicity;
  pattern.lattice = cell;
  const double valid = mask.empty() ? static_cast<double>(rgb.total()) : cv::countNonZero(mask);
  pattern.repeats = valid / cell.cellArea();
  cv::Mat even = rgb;
  if (!shading.empty()) {
    if (shading.size() == rgb.size()) {
      pattern.shading = shading;
    } else {
      cv::resize(shading, pattern.shading, rgb.size(), 0, 0, cv::INTER_LINEAR);
    }
    pattern.shading_spread = shadingSpread(pattern.shading, mask);
    even = unshaded(rgb, pattern.shading);
  }
  const cv::Size size = tileSize(cell);
  averageTile(even, mask, cell, size.width, size.height, pattern.tile_rgb, pattern.tile_mask,
              config.max_tile_repetitions);
  const TilingError tiling = tilingError(even, mask, pattern.tile_rgb, pattern.tile_mask, cell);
  Faithfulness judged = judgeTiling(even, tiling, config);
  pattern.psnr_db = judged.psnr_db;
  pattern.explained = judged.explained;
  pattern.unexplained = std::move(judged.unexplained);
  pattern.overlays = std::move(judged.overlays);
  unexplained_share = judged.unexplained_share;
  return pattern;
}

// Empty when faithful, else why not.
std::string unfaithfulness(const Pattern& p, double unexplained_share,
                           const PatternConfig& config) {
  if (p.repeats < config.min_repeats) return fmt::format("too few repeats ({:.1f})", p.repeats);
  if (unexplained_share > config.max_overlay_share) {
    return fmt::format("the tiling leaves {:.0f} % unexplained", 100.0 * unexplained_share);
  }
  if (p.explained < config.min_explained) {
    return fmt::format("the tiling explains {:.0f} % of the variance", 100.0 * p.explained);
  }
  if (p.psnr_db < config.min_tiling_psnr_db)
    return fmt::format("the tiling reaches {:.1f} dB", p.psnr_db);
  return {};
}

// A faithful cell can be a multiple of the true one (the autocorrelation's clear peaks missed
// the shortest vectors, as on a sensor's blurred brick wall): the cells of half its area
// (index 2 above it) are tried, and one whose tiling stays as faithful (within
// config.finer_psnr_loss_db) replaces it, until none does.
core::Lattice2 finestFaithful(const Scaled& scaled, core::Lattice2 cell, double psnr_db,
                              Periodicity periodicity, const PatternConfig& config,
                              const cv::Mat& shading) {
  const bool stripes = periodicity == Periodicity::kOneDirection;
  const double shortest = config.lattice.min_period_px;
  for (int round = 0; round < 4; ++round) {
    std::vector<core::Lattice2> finer{{0.5 * cell.v1, cell.v2}};
    if (!stripes) {
      finer.push_back(reduceBasis({cell.v1, 0.5 * cell.v2}));
      finer.push_back(reduceBasis({0.5 * (cell.v1 + cell.v2), cell.v2}));
    }
    std::optional<core::Lattice2> best;
    double best_psnr = psnr_db - config.finer_psnr_loss_db;
    for (const core::Lattice2& candidate : finer) {
      if (candidate.v1.norm() < shortest || (!stripes && candidate.v2.norm() < shortest)) continue;
      double share = 0.0;
      const Pattern trial =
          tileAndJudge(scaled.rgb, scaled.mask, candidate, periodicity, config, shading, share);
      if (unfaithfulness(trial, share, config).empty() && trial.psnr_db >= best_psnr) {
        best = candidate, best_psnr = trial.psnr_db;
      }
    }
    if (!best) break;
    cell = *best;
    psnr_db = best_psnr;
  }
  return cell;
}

}  // namespace

PatternAnalysis analysePattern(const cv::Mat& rgb, const cv::Mat& mask,
                               const PatternConfig& config) {
  const auto start = std::chrono::steady_clock::now();
  if (rgb.empty() || rgb.type() != CV_8UC3) {
    throw core::Error("analysePattern: the bitmap must be a non-empty CV_8UC3");
  }
  if (!mask.empty() && (mask.type() != CV_8UC1 || mask.size() != rgb.size())) {
    throw core::Error("analysePattern: the mask must be CV_8UC1 of the bitmap's size");
  }
  PatternAnalysis analysis;
  const auto finish = [&]() {
    analysis.ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    return analysis;
  };
  const Scaled scaled = scaledForAnalysis(rgb, mask, config);
  LatticeEstimate& estimate = analysis.estimate;
  estimate = estimateOn(scaled, config);
  if (estimate.periodicity == Periodicity::kNone) {
    analysis.reason = "no period in the autocorrelation";
    return finish();
  }
  const bool stripes = estimate.periodicity == Periodicity::kOneDirection;
  core::Lattice2 cell = estimate.lattice;
  // Stripes repeat along themselves with any period: a cell about as long as it is wide.
  if (stripes) cell.v2 = std::max(8.0 * scaled.f, cell.v1.norm()) * cell.v2;

  // Candidates judged on the scaled bitmap; the first faithful one, made as fine as it stays
  // faithful, is built at full size.
  std::optional<core::Lattice2> chosen;
  double share = 0.0;
  const cv::Mat shading = shadingOf(scaled.rgb, scaled.mask, cell, config);
  for (const core::Lattice2& candidate : candidateCells(cell, stripes)) {
    const Pattern trial = tileAndJudge(scaled.rgb, scaled.mask, candidate, estimate.periodicity,
                                       config, shading, share);
    analysis.reason = unfaithfulness(trial, share, config);
    if (analysis.reason.empty()) {
      chosen =
          finestFaithful(scaled, candidate, trial.psnr_db, estimate.periodicity, config, shading);
      break;
    }
  }
  // Back in bitmap texels.
  estimate.lattice.v1 /= scaled.f;
  if (!stripes) estimate.lattice.v2 /= scaled.f;
  if (!chosen) return finish();
  core::Lattice2 full{chosen->v1 / scaled.f, chosen->v2 / scaled.f};
  if (scaled.f < 1.0) full = refineLattice(rgb, mask, full, stripes ? 1 : 2);
  Pattern pattern = tileAndJudge(rgb, mask, full, estimate.periodicity, config, shading, share);
  analysis.reason = unfaithfulness(pattern, share, config);
  if (analysis.reason.empty()) analysis.pattern = std::move(pattern);
  return finish();
}

}  // namespace tessera::pattern
