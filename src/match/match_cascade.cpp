#include "tessera/match/match_cascade.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <optional>

#include <fmt/format.h>
#include <spdlog/spdlog.h>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/video/tracking.hpp>

#include "tessera/match/cross_correlation.h"
#include "tessera/match/fidelity.h"

namespace tessera::match {

namespace {

// Tile pixel -> the same pixel after cv::rotate by `turns` quarter turns clockwise, inverted:
// the similarity from the rotated tile's pixels back to the original's (W x H original).
core::Similarity2 unrotate(int turns, int width, int height) {
  const double w1 = width - 1.0, h1 = height - 1.0;
  switch (turns % 4) {
    case 1:  // clockwise: rotated (X, Y) = (h1 - r, c), so (c, r) = (Y, h1 - X)
      return {0.0, -1.0, 0.0, h1};
    case 2:  // (X, Y) = (w1 - c, h1 - r)
      return {-1.0, 0.0, w1, h1};
    case 3:  // counter-clockwise: (X, Y) = (r, w1 - c), so (c, r) = (w1 - Y, X)
      return {0.0, 1.0, w1, 0.0};
    default:
      return {};
  }
}

// The best placement of a stored texture that overlaps the new bitmap in part, at any quarter
// turn: found on both scaled to at most kCoarsePx a side (masked NCC over every shift, by DFT),
// then refined at full size around it. Placements sharing fewer than kMinOverlapShare of the
// smaller mask's texels are not considered (the acceptance rule's coverage decides the rest).
TurnedPeak findPartialOverlap(const cv::Mat& query_grey, const cv::Mat& query_mask,
                              const cv::Mat& stored_grey, const cv::Mat& stored_mask) {
  constexpr double kCoarsePx = 192.0;
  constexpr double kMinOverlapShare = 0.3;
  const cv::Mat full_query_mask =
      query_mask.empty() ? cv::Mat(query_grey.size(), CV_8UC1, cv::Scalar(255)) : query_mask;
  const cv::Mat full_stored_mask =
      stored_mask.empty() ? cv::Mat(stored_grey.size(), CV_8UC1, cv::Scalar(255)) : stored_mask;
  const int longest =
      std::max({query_grey.cols, query_grey.rows, stored_grey.cols, stored_grey.rows});
  const double f = std::min(1.0, kCoarsePx / longest);
  const auto small = [f](const cv::Mat& image, int interpolation) {
    if (f >= 1.0) return image;
    cv::Mat out;
    cv::resize(image, out, cv::Size(), f, f, interpolation);
    return out;
  };
  const double min_overlap = kMinOverlapShare * std::min(cv::countNonZero(full_query_mask),
                                                         cv::countNonZero(full_stored_mask));
  const cv::Mat q = small(query_grey, cv::INTER_AREA);
  const cv::Mat qm = small(full_query_mask, cv::INTER_NEAREST);
  TurnedPeak best =
      findOverlapAtAnyTurn(q, qm, small(stored_grey, cv::INTER_AREA),
                           small(full_stored_mask, cv::INTER_NEAREST), min_overlap * f * f);
  if (best.peak.score <= -1.0 || f >= 1.0) return best;
  const CorrelationPeak start{static_cast<int>(std::lround(best.peak.x / f)),
                              static_cast<int>(std::lround(best.peak.y / f)), best.peak.score};
  best.peak = refineOverlap(query_grey, full_query_mask, turned(stored_grey, best.turns),
                            turned(full_stored_mask, best.turns), start,
                            static_cast<int>(std::ceil(1.0 / f)) + 1, min_overlap);
  return best;
}

// Zero-mean normalised correlation of two RGB images over `mask` (grey levels): whether the
// render follows the patch's structure, not only its mean colour.
double structureAgreement(const cv::Mat& a, const cv::Mat& b, const cv::Mat& mask) {
  cv::Mat ga = greyForCorrelation(a, mask), gb = greyForCorrelation(b, mask);
  cv::Scalar ma, sa, mb, sb;
  cv::meanStdDev(ga, ma, sa, mask);
  cv::meanStdDev(gb, mb, sb, mask);
  if (sa[0] < 1e-6 || sb[0] < 1e-6) return 0.0;
  cv::Mat da = ga - ma[0], db = gb - mb[0];
  cv::Mat product = da.mul(db);
  return cv::mean(product, mask)[0] / (sa[0] * sb[0]);
}

}  // namespace

std::shared_ptr<StoredTexture> patternTexture(std::int64_t id, const cv::Mat& tile_rgb,
                                              const cv::Mat& tile_mask,
                                              const core::Lattice2& lattice,
                                              const MatchConfig& config) {
  auto stored = std::make_shared<StoredTexture>();
  stored->id = id;
  stored->pattern = true;
  stored->lattice = lattice;
  stored->tile_rgb = tile_rgb;
  stored->tile_mask =
      tile_mask.empty() ? cv::Mat(tile_rgb.size(), CV_8UC1, cv::Scalar(255)) : tile_mask;
  // The cell's bounding box in the frame: the template NCC looks for in a new bitmap (any
  // placement of it is the pattern at some phase).
  const Eigen::Vector2d corners[] = {Eigen::Vector2d::Zero(), lattice.v1, lattice.v2,
                                     lattice.v1 + lattice.v2};
  Eigen::Vector2d low = corners[0], high = corners[0];
  for (const Eigen::Vector2d& c : corners) low = low.cwiseMin(c), high = high.cwiseMax(c);
  stored->swatch_origin = low.array().floor();
  const auto swatch = [&](double width, double height) {
    return renderPattern(stored->tile_rgb, stored->tile_mask, lattice,
                         {1.0, 0.0, stored->swatch_origin.x(), stored->swatch_origin.y()},
                         std::max(1, static_cast<int>(std::ceil(width))),
                         std::max(1, static_cast<int>(std::ceil(height))));
  };
  const Rendered cell =
      swatch(high.x() - stored->swatch_origin.x(), high.y() - stored->swatch_origin.y());
  stored->description.rgb = cell.rgb;
  stored->description.mask = cell.covered;
  // Colour coherence judged on a swatch of several cells, as a wall's bitmap shows them.
  const double side = std::max({256.0, 2.0 * (high.x() - low.x()), 2.0 * (high.y() - low.y())});
  const Rendered large = swatch(side, side);
  stored->description.ccv = computeCcv(large.rgb, large.covered, config.ccv);
  return stored;
}

Rendered renderStored(const StoredTexture& stored, const core::Similarity2& patch_to_texture,
                      int width, int height) {
  if (stored.pattern) {
    return renderPattern(stored.tile_rgb, stored.tile_mask, stored.lattice, patch_to_texture, width,
                         height);
  }
  return renderThrough(stored.description.rgb, stored.description.mask, patch_to_texture, width,
                       height, false);
}

namespace {

// `rgb` and `mask` as they are described: at most config.describe_max_px long.
struct DescribedSize {
  cv::Mat rgb, mask;
  double scale = 1.0;  // described size over full size
};

DescribedSize describedSize(const cv::Mat& rgb, const cv::Mat& mask, const MatchConfig& config) {
  const int longest = std::max(rgb.cols, rgb.rows);
  if (config.describe_max_px <= 0 || longest <= config.describe_max_px) return {rgb, mask, 1.0};
  DescribedSize small;
  small.scale = static_cast<double>(config.describe_max_px) / longest;
  cv::resize(rgb, small.rgb, cv::Size(), small.scale, small.scale, cv::INTER_AREA);
  cv::resize(mask, small.mask, small.rgb.size(), 0, 0, cv::INTER_NEAREST);
  return small;
}

// The CCV of `described`.
Ccv describedCcv(const DescribedSize& described, CcvConfig ccv) {
  if (described.scale != 1.0) {  // coherence is judged in full-size texels
    const double area = described.scale * described.scale;
    ccv.min_coherent_px = std::max(1, static_cast<int>(std::lround(ccv.min_coherent_px * area)));
  }
  return computeCcv(described.rgb, described.mask, ccv);
}

TextureDescription withMask(const cv::Mat& rgb, const cv::Mat& mask) {
  TextureDescription description;
  description.rgb = rgb;
  description.mask = mask.empty() ? cv::Mat(rgb.size(), CV_8UC1, cv::Scalar(255)) : mask;
  return description;
}

}  // namespace

TextureDescription describeColours(const cv::Mat& rgb, const cv::Mat& mask,
                                   const MatchConfig& config) {
  TextureDescription description = withMask(rgb, mask);
  description.ccv = describedCcv(describedSize(rgb, description.mask, config), config.ccv);
  return description;
}

TextureDescription describeTexture(const cv::Mat& rgb, const cv::Mat& mask,
                                   const MatchConfig& config) {
  TextureDescription description = withMask(rgb, mask);
  const DescribedSize described = describedSize(rgb, description.mask, config);
  description.ccv = describedCcv(described, config.ccv);
  description.features = detectFeatures(described.rgb, described.mask, config.features);
  if (described.scale == 1.0) return description;
  // Back to full-size pixel centres: x_full + 0.5 = (x_small + 0.5) / f.
  const double f = described.scale;
  for (cv::KeyPoint& k : description.features.keypoints) {
    k.pt = cv::Point2f(static_cast<float>((k.pt.x + 0.5) / f - 0.5),
                       static_cast<float>((k.pt.y + 0.5) / f - 0.5));
    k.size = static_cast<float>(k.size / f);
  }
  return description;
}

MemoryCatalog::MemoryCatalog(const CcvConfig& ccv) : index_(ccvLength(ccv)) {}

void MemoryCatalog::add(std::shared_ptr<const StoredTexture> texture) {
  index_.add(texture->id, texture->description.ccv.values);
  const auto at = std::lower_bound(
      textures_.begin(), textures_.end(), texture->id,
      [](const std::shared_ptr<const StoredTexture>& t, std::int64_t id) { return t->id < id; });
  textures_.insert(at, std::move(texture));
}

std::vector<CcvNeighbour> MemoryCatalog::nearest(const std::vector<float>& ccv, double max_distance,
                                                 std::size_t k) const {
  return index_.query(ccv, max_distance, k);
}

std::shared_ptr<const StoredTexture> MemoryCatalog::load(std::int64_t id) const {
  const auto at = std::lower_bound(
      textures_.begin(), textures_.end(), id,
      [](const std::shared_ptr<const StoredTexture>& t, std::int64_t key) { return t->id < key; });
  return at != textures_.end() && (*at)->id == id ? *at : nullptr;
}

std::optional<core::Similarity2> MatchCascade::findPattern(const TextureDescription& query,
                                                           const StoredTexture& stored,
                                                           CandidateVerdict& verdict) const {
  // The stored image is looked for inside the new one (a pattern tile, or a single texture
  // smaller than the patch), else the new one inside the stored one, each at any quarter turn.
  const cv::Mat query_grey = greyForCorrelation(query.rgb, query.mask);
  const cv::Mat stored_grey = greyForCorrelation(stored.description.rgb, stored.description.mask);
  // Stored turned inside the new one at `offset`: new texel p -> turned stored p - offset.
  const auto storedInside = [&](const TurnedPeak& found) {
    const core::Similarity2 shift{1.0, 0.0, -static_cast<double>(found.peak.x),
                                  -static_cast<double>(found.peak.y)};
    return shift.then(unrotate(found.turns, stored_grey.cols, stored_grey.rows));
  };
  const TurnedPeak inside = findTileAtAnyTurn(query_grey, stored_grey);
  double best = inside.peak.score;
  core::Similarity2 new_to_stored = storedInside(inside);
  if (!stored.pattern) {
    // New turned inside the stored one: new texel p -> turned new texel -> + offset.
    const TurnedPeak around = findTileAtAnyTurn(stored_grey, query_grey);
    if (around.peak.score > best) {
      best = around.peak.score;
      const core::Similarity2 shift{1.0, 0.0, static_cast<double>(around.peak.x),
                                    static_cast<double>(around.peak.y)};
      new_to_stored =
          unrotate(around.turns, query_grey.cols, query_grey.rows).inverse().then(shift);
    }
  }
  // Neither inside the other (the same floor seen from two places): the placement over the
  // texels both cover.
  if (!stored.pattern && best < config_.ncc_min_score) {
    const TurnedPeak overlap =
        findPartialOverlap(query_grey, query.mask, stored_grey, stored.description.mask);
    if (overlap.peak.score > best) best = overlap.peak.score, new_to_stored = storedInside(overlap);
  }
  verdict.method = "ncc";
  if (best < config_.ncc_min_score) {
    verdict.reason = fmt::format("NCC peak {:.2f} < {:.2f}", best, config_.ncc_min_score);
    return std::nullopt;
  }
  // Swatch pixel -> texture frame (a pattern's swatch starts at swatch_origin).
  const core::Similarity2 to_frame{1.0, 0.0, stored.swatch_origin.x(), stored.swatch_origin.y()};
  return new_to_stored.then(to_frame);
}

std::optional<core::Similarity2> refinedByEcc(const TextureDescription& query,
                                              const StoredTexture& stored,
                                              const core::Similarity2& patch_to_texture,
                                              const Rendered* rendered) {
  const Rendered render =
      rendered != nullptr ? *rendered
                          : renderStored(stored, patch_to_texture, query.rgb.cols, query.rgb.rows);
  cv::Mat both;
  cv::bitwise_and(query.mask, render.covered, both);
  const cv::Mat query_grey = greyForCorrelation(query.rgb, both);
  const cv::Mat render_grey = greyForCorrelation(render.rgb, both);
  cv::Mat warp = cv::Mat::eye(2, 3, CV_32F);
  try {
    cv::findTransformECC(
        query_grey, render_grey, warp, cv::MOTION_AFFINE,
        cv::TermCriteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 30, 1e-4), both, 5);
  } catch (const cv::Exception&) {  // no convergence
    return std::nullopt;
  }
  const auto at = [&warp](int r, int c) { return static_cast<double>(warp.at<float>(r, c)); };
  const core::Similarity2 correction{(at(0, 0) + at(1, 1)) / 2.0, (at(1, 0) - at(0, 1)) / 2.0,
                                     at(0, 2), at(1, 2)};
  return correction.then(patch_to_texture);
}

CandidateVerdict MatchCascade::tryCandidate(const TextureDescription& query,
                                            const StoredTexture& stored,
                                            double ccv_distance) const {
  CandidateVerdict verdict;
  verdict.id = stored.id;
  verdict.ccv_distance = ccv_distance;
  std::optional<core::Similarity2> transform;
  if (!stored.pattern) {
    verdict.method = "features";
    const auto found = matchFeatures(query.features, stored.description.features, config_.features);
    if (found) {
      transform = found->query_to_stored;
    } else {
      verdict.reason = "too few feature matches";
    }
  }
  // Patterns, and single textures that give too few features (plain or fine-grained surfaces
  // at the same scale), by cross-correlation.
  if (!transform) transform = findPattern(query, stored, verdict);
  if (!transform) return verdict;
  verdict.transform = transform;

  const Rendered render = renderStored(stored, *transform, query.rgb.cols, query.rgb.rows);
  const Fidelity fidelity = measureFidelity(query.rgb, query.mask, render);
  verdict.psnr_db = fidelity.psnr_db;
  verdict.coverage = fidelity.coverage;
  cv::Mat compared;
  cv::bitwise_and(query.mask, render.covered, compared);
  const double structure = structureAgreement(query.rgb, render.rgb, compared);
  verdict.reason = config_.refusal(fidelity);
  if (verdict.reason.empty() && structure < config_.ncc_min_score) {
    verdict.reason = fmt::format("structure NCC {:.2f} < {:.2f}", structure, config_.ncc_min_score);
  }
  verdict.accepted = verdict.reason.empty();
  // A feature or correlation estimate is good to about a texel; the map shows the stored
  // texture in place of the patch's, so what is left of the misplacement is what the view loses
  // (the office's second table: 3.0 dB of view PSNR on its pixels at the estimate, 2.0 refined).
  if (verdict.accepted && !stored.pattern) {
    if (const auto refined = refinedByEcc(query, stored, *transform, &render)) {
      const Fidelity better = measureFidelity(
          query.rgb, query.mask, renderStored(stored, *refined, query.rgb.cols, query.rgb.rows));
      spdlog::debug("candidate {}: ECC {:.2f} -> {:.2f} dB, coverage {:.3f} -> {:.3f}", stored.id,
                    fidelity.psnr_db, better.psnr_db, fidelity.coverage, better.coverage);
      if (better.psnr_db > fidelity.psnr_db && config_.refusal(better).empty()) {
        verdict.transform = refined;
        verdict.psnr_db = better.psnr_db;
        verdict.coverage = better.coverage;
      }
    }
  }
  return verdict;
}

std::string MatchConfig::refusal(const Fidelity& fidelity) const {
  if (fidelity.coverage < min_coverage) {
    return fmt::format("covers {:.0f} % of the patch", 100.0 * fidelity.coverage);
  }
  if (fidelity.psnr_db < min_psnr_db) {
    return fmt::format("PSNR {:.1f} dB < {:.1f}", fidelity.psnr_db, min_psnr_db);
  }
  return {};
}

MatchDecision MatchCascade::match(const TextureDescription& query, const TextureCatalog& catalog,
                                  const PrecheckedVerdicts* prechecked) const {
  return run(query, catalog, prechecked, nullptr);
}

PrecheckedVerdicts MatchCascade::precheck(const TextureDescription& query,
                                          const TextureCatalog& catalog) const {
  PrecheckedVerdicts seen;
  seen.ms = run(query, catalog, nullptr, &seen).ms;
  return seen;
}

const CandidateVerdict* PrecheckedVerdicts::find(const StoredTexture& stored) const {
  for (const auto& [texture, verdict] : verdicts) {
    if (texture.lock().get() == &stored) return &verdict;
  }
  return nullptr;
}

MatchDecision MatchCascade::run(const TextureDescription& query, const TextureCatalog& catalog,
                                const PrecheckedVerdicts* prechecked,
                                PrecheckedVerdicts* seen) const {
  const auto start = std::chrono::steady_clock::now();
  MatchDecision decision;
  decision.considered = catalog.size();
  const std::vector<CcvNeighbour> candidates =
      catalog.nearest(query.ccv.values, config_.ccv_max_distance, config_.max_candidates);
  decision.passed_ccv = candidates.size();
  for (const CcvNeighbour& candidate : candidates) {
    const std::shared_ptr<const StoredTexture> stored = catalog.load(candidate.id);
    if (!stored) continue;
    const CandidateVerdict* known = prechecked != nullptr ? prechecked->find(*stored) : nullptr;
    CandidateVerdict verdict =
        known != nullptr ? *known : tryCandidate(query, *stored, candidate.distance);
    verdict.ccv_distance = candidate.distance;
    if (seen != nullptr) seen->verdicts.emplace_back(stored, verdict);
    decision.verdicts.push_back(verdict);
    if (verdict.accepted) {
      decision.match = std::move(verdict);
      break;
    }
  }
  decision.ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  return decision;
}

}  // namespace tessera::match
