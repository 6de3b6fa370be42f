#include "tessera/pattern/pattern_extractor.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdint>

#include <fmt/format.h>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "tessera/core/error.h"
#include "tessera/match/fidelity.h"
#include "lattice_refinement.h"

namespace tessera::pattern {

namespace {

// Bilinear colour at (x, y) when all four neighbours are valid texels.
bool sampleValid(const cv::Mat& rgb, const cv::Mat& mask, double x, double y,
                 std::array<float, 3>& colour) {
  const int x0 = static_cast<int>(std::floor(x)), y0 = static_cast<int>(std::floor(y));
  if (x0 < 0 || y0 < 0 || x0 + 1 >= rgb.cols || y0 + 1 >= rgb.rows) return false;
  if (!mask.empty() && (mask.at<std::uint8_t>(y0, x0) == 0 || mask.at<std::uint8_t>(y0, x0 + 1) == 0 ||
                        mask.at<std::uint8_t>(y0 + 1, x0) == 0 ||
                        mask.at<std::uint8_t>(y0 + 1, x0 + 1) == 0)) {
    return false;
  }
  const double fx = x - x0, fy = y - y0;
  const auto& p00 = rgb.at<cv::Vec3b>(y0, x0);
  const auto& p01 = rgb.at<cv::Vec3b>(y0, x0 + 1);
  const auto& p10 = rgb.at<cv::Vec3b>(y0 + 1, x0);
  const auto& p11 = rgb.at<cv::Vec3b>(y0 + 1, x0 + 1);
  for (int c = 0; c < 3; ++c) {
    colour[static_cast<std::size_t>(c)] = static_cast<float>(
        (1 - fy) * ((1 - fx) * p00[c] + fx * p01[c]) + fy * ((1 - fx) * p10[c] + fx * p11[c]));
  }
  return true;
}

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
Faithfulness judgeTiling(const cv::Mat& rgb, const cv::Mat& mask, const cv::Mat& tiled,
                         const cv::Mat& covered, const PatternConfig& config) {
  Faithfulness out;
  cv::Mat valid = covered.clone();
  if (!mask.empty()) cv::bitwise_and(valid, mask, valid);
  const int valid_count = cv::countNonZero(valid);
  if (valid_count == 0) return out;

  // Per-texel colour error (RMS over the channels) and its robust spread.
  cv::Mat a, b, diff, error;
  rgb.convertTo(a, CV_32FC3);
  tiled.convertTo(b, CV_32FC3);
  cv::absdiff(a, b, diff);
  diff = diff.mul(diff);
  cv::transform(diff, error, cv::Matx13f(1.0f / 3, 1.0f / 3, 1.0f / 3));
  cv::sqrt(error, error);
  std::vector<float> errors;
  errors.reserve(static_cast<std::size_t>(valid_count));
  for (int row = 0; row < error.rows; ++row) {
    const auto* e = error.ptr<float>(row);
    const auto* v = valid.ptr<std::uint8_t>(row);
    for (int col = 0; col < error.cols; ++col) {
      if (v[col] != 0) errors.push_back(e[col]);
    }
  }
  const auto middle = errors.begin() + static_cast<long>(errors.size() / 2);
  std::nth_element(errors.begin(), middle, errors.end());
  const double sigma = 1.4826 * *middle;
  const double threshold = std::max(config.overlay_sigmas * sigma, config.min_overlay_error);

  // Unexplained blobs: the error, averaged over a few texels so that an object's texels that
  // happen to resemble the pattern still count as the object's, above the threshold, in
  // blobs of at least min_overlay_px texels, holes filled.
  cv::Mat smooth;
  cv::blur(error, smooth, {7, 7});
  cv::Mat high = (smooth > threshold) & valid;
  std::vector<std::vector<cv::Point>> contours;
  cv::findContours(high, contours, cv::RETR_EXTERNAL, cv::CHAIN_APPROX_SIMPLE);
  out.unexplained = cv::Mat(rgb.size(), CV_8UC1, cv::Scalar(0));
  for (std::size_t i = 0; i < contours.size(); ++i) {
    if (cv::contourArea(contours[i]) < config.min_overlay_px) continue;
    cv::drawContours(out.unexplained, contours, static_cast<int>(i), cv::Scalar(255), cv::FILLED);
    out.overlays.push_back(cv::boundingRect(contours[i]));
  }
  cv::dilate(out.unexplained, out.unexplained,
             cv::getStructuringElement(cv::MORPH_ELLIPSE, {5, 5}));
  out.unexplained &= valid;
  std::sort(out.overlays.begin(), out.overlays.end(),
            [](const cv::Rect& p, const cv::Rect& q) { return p.area() > q.area(); });
  out.unexplained_share = cv::countNonZero(out.unexplained) / static_cast<double>(valid_count);

  // PSNR and explained variance over the texels the tiling explains.
  const cv::Mat explained = valid & (out.unexplained == 0);
  const double n = cv::countNonZero(explained);
  if (n < 1.0) return out;
  diff.setTo(cv::Scalar::all(0), explained == 0);
  const cv::Scalar residual = cv::sum(diff);
  cv::Scalar mean, stddev;
  cv::meanStdDev(a, mean, stddev, explained);
  const double sse_total = residual[0] + residual[1] + residual[2];
  const double sst = n * (stddev[0] * stddev[0] + stddev[1] * stddev[1] + stddev[2] * stddev[2]);
  const double mse = sse_total / (3.0 * n);
  out.psnr_db = mse > 0.0 ? std::min(99.0, 10.0 * std::log10(255.0 * 255.0 / mse)) : 99.0;
  out.explained = sst > 0.0 ? 1.0 - sse_total / sst : 0.0;
  return out;
}

// The grey image with its local mean removed and its local contrast made one (normalised
// convolution over the mask, Gaussian of `sigma`): a bright occluder or a lighting gradient
// would otherwise dominate the autocorrelation with its own broad bump.
cv::Mat locallyNormalised(const cv::Mat& grey, const cv::Mat& mask, double sigma) {
  cv::Mat m(grey.size(), CV_32FC1, cv::Scalar(1));
  if (!mask.empty()) m.setTo(0.0f, mask == 0);
  const auto masked_blur = [&m, sigma](const cv::Mat& image) {
    cv::Mat num, den;
    cv::GaussianBlur(image.mul(m), num, cv::Size(), sigma);
    cv::GaussianBlur(m, den, cv::Size(), sigma);
    return cv::Mat(num / cv::max(den, 1e-3));
  };
  const cv::Mat centred = grey - masked_blur(grey);
  cv::Mat deviation;
  cv::sqrt(masked_blur(centred.mul(centred)), deviation);
  // 2 grey levels of floor: a plain region stays low instead of becoming amplified noise.
  const cv::Mat out = centred / (deviation + 2.0f);
  return out.mul(m);
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

// The repeat cost of shift d (see RepeatCost), over valid pairs centred on every third row
// and column; nothing when too few pairs exist.
std::optional<RepeatCost> repeatError(const cv::Mat& rgb, const cv::Mat& mask,
                                      const Eigen::Vector2d& d) {
  std::vector<float> errors;
  errors.reserve(rgb.total() / 9 + 1);
  // Compared at x - d/2 and x + d/2, so that both samples are interpolated by the same
  // fraction of a texel: a shift between texels is not judged worse for being smoothed.
  std::array<float, 3> back{}, ahead{};
  std::array<double, 3> colour_sum{}, colour_squares{};
  const Eigen::Vector2d half = 0.5 * d;
  for (int row = 0; row < rgb.rows; row += 3) {
    for (int col = 0; col < rgb.cols; col += 3) {
      if (!sampleValid(rgb, mask, col - half.x(), row - half.y(), back) ||
          !sampleValid(rgb, mask, col + half.x(), row + half.y(), ahead)) {
        continue;
      }
      float sum = 0.0f;
      for (std::size_t c = 0; c < 3; ++c) {
        sum += (ahead[c] - back[c]) * (ahead[c] - back[c]);
        colour_sum[c] += back[c];
        colour_squares[c] += back[c] * back[c];
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
  grey = locallyNormalised(grey, scaled.mask,
                           std::max(8.0, std::max(grey.cols, grey.rows) / 8.0));
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

// The cell's tile built from `rgb` and judged against it.
Pattern tileAndJudge(const cv::Mat& rgb, const cv::Mat& mask, const core::Lattice2& cell,
                     Periodicity periodicity, const PatternConfig& config,
                     double& unexplained_share) {
  Pattern pattern;
  pattern.periodicity = periodicity;
  pattern.lattice = cell;
  const double valid = mask.empty() ? static_cast<double>(rgb.total()) : cv::countNonZero(mask);
  pattern.repeats = valid / cell.cellArea();
  const cv::Size size = tileSize(cell);
  averageTile(rgb, mask, cell, size.width, size.height, pattern.tile_rgb, pattern.tile_mask);
  const match::Rendered tiled = match::renderPattern(pattern.tile_rgb, pattern.tile_mask, cell,
                                                     core::Similarity2{}, rgb.cols, rgb.rows);
  Faithfulness judged = judgeTiling(rgb, mask, tiled.rgb, tiled.covered, config);
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
  if (p.psnr_db < config.min_psnr_db) return fmt::format("the tiling reaches {:.1f} dB", p.psnr_db);
  return {};
}

}  // namespace

void averageTile(const cv::Mat& rgb, const cv::Mat& mask, const core::Lattice2& lattice, int width,
                 int height, cv::Mat& tile_rgb, cv::Mat& tile_mask) {
  tile_rgb = cv::Mat(height, width, CV_8UC3, cv::Scalar::all(0));
  tile_mask = cv::Mat(height, width, CV_8UC1, cv::Scalar(0));
  // The range of cells (n, m) that reach the bitmap: its corners in lattice coordinates.
  Eigen::Vector2d low(1e18, 1e18), high(-1e18, -1e18);
  for (const Eigen::Vector2d& corner :
       {Eigen::Vector2d(0, 0), Eigen::Vector2d(rgb.cols, 0), Eigen::Vector2d(0, rgb.rows),
        Eigen::Vector2d(rgb.cols, rgb.rows)}) {
    const Eigen::Vector2d c = lattice.coordinatesOf(corner);
    low = low.cwiseMin(c);
    high = high.cwiseMax(c);
  }
  const int n0 = static_cast<int>(std::floor(low.x())) - 1, n1 = static_cast<int>(std::ceil(high.x()));
  const int m0 = static_cast<int>(std::floor(low.y())) - 1, m1 = static_cast<int>(std::ceil(high.y()));
  std::array<std::vector<float>, 3> samples;
  std::array<float, 3> colour{};
  for (int j = 0; j < height; ++j) {
    for (int i = 0; i < width; ++i) {
      const Eigen::Vector2d q0 = (i / static_cast<double>(width)) * lattice.v1 +
                                 (j / static_cast<double>(height)) * lattice.v2;
      for (auto& s : samples) s.clear();
      for (int m = m0; m <= m1; ++m) {
        for (int n = n0; n <= n1; ++n) {
          const Eigen::Vector2d q = q0 + n * lattice.v1 + m * lattice.v2;
          if (!sampleValid(rgb, mask, q.x(), q.y(), colour)) continue;
          for (std::size_t c = 0; c < 3; ++c) samples[c].push_back(colour[c]);
        }
      }
      if (samples[0].empty()) continue;
      cv::Vec3b& out = tile_rgb.at<cv::Vec3b>(j, i);
      for (std::size_t c = 0; c < 3; ++c) {
        auto& s = samples[c];
        const auto middle = s.begin() + static_cast<long>(s.size() / 2);
        std::nth_element(s.begin(), middle, s.end());
        out[static_cast<int>(c)] = cv::saturate_cast<std::uint8_t>(*middle);
      }
      tile_mask.at<std::uint8_t>(j, i) = 255;
    }
  }
}

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
    analysis.ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
                      .count();
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

  // Candidates judged on the scaled bitmap; the first faithful one is built at full size.
  std::optional<core::Lattice2> chosen;
  double share = 0.0;
  for (const core::Lattice2& candidate : candidateCells(cell, stripes)) {
    const Pattern trial =
        tileAndJudge(scaled.rgb, scaled.mask, candidate, estimate.periodicity, config, share);
    analysis.reason = unfaithfulness(trial, share, config);
    if (analysis.reason.empty()) {
      chosen = candidate;
      break;
    }
  }
  // Back in bitmap texels.
  estimate.lattice.v1 /= scaled.f;
  if (!stripes) estimate.lattice.v2 /= scaled.f;
  if (!chosen) return finish();
  core::Lattice2 full{chosen->v1 / scaled.f, chosen->v2 / scaled.f};
  if (scaled.f < 1.0) full = refineLattice(rgb, mask, full, stripes ? 1 : 2);
  Pattern pattern = tileAndJudge(rgb, mask, full, estimate.periodicity, config, share);
  analysis.reason = unfaithfulness(pattern, share, config);
  if (analysis.reason.empty()) analysis.pattern = std::move(pattern);
  return finish();
}

}  // namespace tessera::pattern
