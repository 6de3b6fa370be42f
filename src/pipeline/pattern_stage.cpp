// The match stage's pattern step: a bitmap that matched nothing is analysed for a periodic
// pattern. Boxes the tiling does not explain (a poster on a brick wall) become overlays,
// matched against the database like any bitmap; the explained rest may reuse a stored
// pattern. The plan replaces the bitmap only if the pattern with its overlays drawn on top
// shows the whole bitmap as faithfully as a reuse must.
#include <algorithm>

#include <spdlog/spdlog.h>
#include <opencv2/core.hpp>

#include "tessera/match/pattern_alignment.h"
#include "tessera/pipeline/texture_db_stages.h"

namespace tessera::pipeline {

namespace {

// Overlay blobs worth their own texture, as boxes grown by the margin; boxes that then
// overlap are merged.
std::vector<cv::Rect> overlayBoxes(const pattern::Pattern& found, const cv::Size& size,
                                   const pattern::PatternStageConfig& config) {
  const int m = config.overlay_margin_px;
  const cv::Rect bitmap(0, 0, size.width, size.height);
  std::vector<cv::Rect> boxes;
  for (const cv::Rect& blob : found.overlays) {
    if (std::min(blob.width, blob.height) < config.min_overlay_side_px ||
        blob.area() < config.min_overlay_area_px) {
      continue;
    }
    boxes.push_back(cv::Rect(blob.x - m, blob.y - m, blob.width + 2 * m, blob.height + 2 * m) &
                    bitmap);
  }
  for (bool merged = true; merged;) {
    merged = false;
    for (std::size_t i = 0; i < boxes.size() && !merged; ++i) {
      for (std::size_t j = i + 1; j < boxes.size() && !merged; ++j) {
        if ((boxes[i] & boxes[j]).area() == 0) continue;
        boxes[i] |= boxes[j];
        boxes.erase(boxes.begin() + static_cast<std::ptrdiff_t>(j));
        merged = true;
      }
    }
  }
  return boxes;
}

}  // namespace

std::optional<match::CandidateVerdict> reuseStoredPattern(
    const pattern::Pattern& found, const match::TextureDescription& shown,
    const std::vector<PatternCandidate>& candidates, const match::MatchConfig& config) {
  for (const PatternCandidate& candidate : candidates) {
    const match::StoredTexture& stored = *candidate.texture;
    match::CandidateVerdict verdict;
    verdict.id = stored.id;
    verdict.ccv_distance = candidate.ccv_distance;
    verdict.method = "lattice";
    verdict.transform = match::alignPattern(found.tile_rgb, found.tile_mask, found.lattice, stored);
    if (!verdict.transform) continue;
    verdict.transform = match::refineAlignment(shown.rgb, shown.mask, stored, *verdict.transform);
    const match::Fidelity fidelity = match::measureFidelity(
        shown.rgb, shown.mask,
        match::renderStored(stored, *verdict.transform, shown.rgb.cols, shown.rgb.rows));
    verdict.psnr_db = fidelity.psnr_db;
    verdict.coverage = fidelity.coverage;
    spdlog::debug("pattern vs stored pattern {}: {:.1f} dB over {:.0f} %", stored.id,
                  fidelity.psnr_db, 100.0 * fidelity.coverage);
    if (fidelity.psnr_db >= config.min_psnr_db && fidelity.coverage >= config.min_coverage) {
      verdict.accepted = true;
      return verdict;
    }
  }
  return std::nullopt;
}

core::Similarity2 patchToBox(const cv::Rect& box) {
  return {1.0, 0.0, -static_cast<double>(box.x), -static_cast<double>(box.y)};
}

match::Fidelity layeredFidelity(const match::TextureDescription& bitmap, const PatternPlan& plan,
                                const match::TextureCatalog& catalog) {
  const int w = bitmap.rgb.cols, h = bitmap.rgb.rows;
  match::Rendered shown;
  const auto reused = plan.base_reuse ? catalog.load(plan.base_reuse->id) : nullptr;
  if (reused) {
    shown = match::renderStored(*reused, *plan.base_reuse->transform, w, h);
  } else {
    shown = match::renderPattern(plan.found.tile_rgb, plan.found.tile_mask, plan.found.lattice, {},
                                 w, h);
  }
  for (const OverlayMatch& overlay : plan.overlays) {
    const cv::Rect& box = overlay.box;
    const auto& match = overlay.decision.match;
    const auto stored = match ? catalog.load(match->id) : nullptr;
    if (stored) {  // the reused texture, through the crop's transform
      const match::Rendered part =
          match::renderStored(*stored, *match->transform, box.width, box.height);
      part.rgb.copyTo(shown.rgb(box), part.covered);
      cv::Mat covered = shown.covered(box);
      covered |= part.covered;
    } else {  // its own pixels
      overlay.description.rgb.copyTo(shown.rgb(box), overlay.description.mask);
      cv::Mat covered = shown.covered(box);
      covered |= overlay.description.mask;
    }
  }
  return match::measureFidelity(bitmap.rgb, bitmap.mask, shown);
}

void MatchStage::findPattern(MatchedPatch& matched) const {
  const match::TextureDescription& bitmap = *matched.description;
  try {
    pattern::PatternAnalysis analysis =
        pattern::analysePattern(bitmap.rgb, bitmap.mask, patterns_.extractor);
    matched.pattern_ms = analysis.ms;
    if (!analysis.pattern) return;
    const SteadyTime start = std::chrono::steady_clock::now();
    matched.pattern = planPattern(bitmap, std::move(*analysis.pattern));
    matched.pattern_ms +=
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  } catch (const std::exception& e) {  // the bitmap is then stored as it is
    spdlog::warn("patch {} version {}: no pattern analysis: {}", matched.bitmap->id,
                 matched.bitmap->version, e.what());
  }
}

std::optional<PatternPlan> MatchStage::planPattern(const match::TextureDescription& bitmap,
                                                   pattern::Pattern found) const {
  PatternPlan plan;
  plan.found = std::move(found);
  const std::vector<cv::Rect> boxes = overlayBoxes(plan.found, bitmap.rgb.size(), patterns_);
  if (!boxes.empty()) {
    // The explained rest may be a pattern the database has (the other brick wall's).
    cv::Mat base_mask = bitmap.mask.clone();
    for (const cv::Rect& box : boxes) base_mask(box).setTo(0);
    plan.base = match::describeTexture(bitmap.rgb, base_mask, cascade_.config());
  }
  const auto lock = catalog_.readLock();
  {
    std::vector<PatternCandidate> candidates;
    const match::TextureDescription& rest = plan.base ? *plan.base : bitmap;
    for (const match::CcvNeighbour& n :
         catalog_.nearest(rest.ccv.values, cascade_.config().ccv_max_distance,
                          cascade_.config().max_candidates)) {
      if (auto stored = catalog_.load(n.id); stored && stored->pattern) {
        candidates.push_back({std::move(stored), n.distance});
      }
    }
    plan.base_reuse = reuseStoredPattern(plan.found, rest, candidates, cascade_.config());
  }
  if (!boxes.empty()) {
    for (const cv::Rect& box : boxes) {
      OverlayMatch overlay;
      overlay.box = box;
      overlay.description = match::describeTexture(bitmap.rgb(box).clone(),
                                                   bitmap.mask(box).clone(), cascade_.config());
      overlay.decision = cascade_.match(overlay.description, catalog_);
      plan.overlays.push_back(std::move(overlay));
    }
  }
  plan.fidelity = layeredFidelity(bitmap, plan, catalog_);
  const match::MatchConfig& limits = cascade_.config();
  if (plan.fidelity.psnr_db >= limits.min_psnr_db &&
      plan.fidelity.coverage >= limits.min_coverage) {
    return plan;
  }
  spdlog::debug(
      "a {}x{} pattern tile with {} overlays shows a {}x{} bitmap at {:.1f} dB over {:.0f} % of "
      "it, short of a reuse's {:.1f} dB over {:.0f} %: stored whole",
      plan.found.tile_rgb.cols, plan.found.tile_rgb.rows, plan.overlays.size(), bitmap.rgb.cols,
      bitmap.rgb.rows, plan.fidelity.psnr_db, 100.0 * plan.fidelity.coverage, limits.min_psnr_db,
      100.0 * limits.min_coverage);
  return std::nullopt;
}

}  // namespace tessera::pipeline
