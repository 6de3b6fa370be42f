#include "tessera/reuse/layer_plan.h"

#include <algorithm>
#include <chrono>

#include <spdlog/spdlog.h>
#include <opencv2/core.hpp>
#include <opencv2/photo.hpp>

#include "tessera/match/pattern_alignment.h"
#include "tessera/pattern/overlays.h"

namespace tessera::reuse {

namespace {

// Overlay blobs worth their own texture, as boxes grown by the margin; boxes that then
// overlap are merged.
std::vector<cv::Rect> overlayBoxes(const std::vector<cv::Rect>& blobs, const cv::Size& size,
                                   const pattern::PatternStageConfig& config) {
  const int m = config.overlay_margin_px;
  const cv::Rect bitmap(0, 0, size.width, size.height);
  std::vector<cv::Rect> boxes;
  for (const cv::Rect& blob : blobs) {
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

match::CandidateVerdict tryStoredPattern(const pattern::Pattern& found,
                                         const match::TextureDescription& shown,
                                         const PatternCandidate& candidate,
                                         const match::MatchConfig& config) {
  const match::StoredTexture& stored = *candidate.texture;
  match::CandidateVerdict verdict;
  verdict.id = stored.id;
  verdict.ccv_distance = candidate.ccv_distance;
  verdict.method = "lattice";
  verdict.transform = match::alignPattern(found.tile_rgb, found.tile_mask, found.lattice, stored);
  if (!verdict.transform) return verdict;
  verdict.transform = match::refineAlignment(shown.rgb, shown.mask, stored, *verdict.transform);
  const match::Fidelity fidelity = match::measureFidelity(
      shown.rgb, shown.mask,
      match::renderStored(stored, *verdict.transform, shown.rgb.cols, shown.rgb.rows));
  verdict.psnr_db = fidelity.psnr_db;
  verdict.coverage = fidelity.coverage;
  verdict.accepted = config.accepts(fidelity);
  return verdict;
}

std::optional<match::CandidateVerdict> reuseStoredPattern(
    const pattern::Pattern& found, const match::TextureDescription& shown,
    const std::vector<PatternCandidate>& candidates, const match::MatchConfig& config,
    const match::PrecheckedVerdicts* prechecked) {
  for (const PatternCandidate& candidate : candidates) {
    const match::CandidateVerdict* ready =
        prechecked != nullptr ? prechecked->find(*candidate.texture) : nullptr;
    match::CandidateVerdict verdict =
        ready != nullptr ? *ready : tryStoredPattern(found, shown, candidate, config);
    verdict.ccv_distance = candidate.ccv_distance;
    if (verdict.accepted) return verdict;
  }
  return std::nullopt;
}

core::Similarity2 patchToBox(const cv::Rect& box) {
  return {1.0, 0.0, -static_cast<double>(box.x), -static_cast<double>(box.y)};
}

match::Fidelity layeredFidelity(const match::TextureDescription& bitmap, const LayerPlan& plan,
                                const match::TextureCatalog& catalog) {
  const int w = bitmap.rgb.cols, h = bitmap.rgb.rows;
  match::Rendered shown;
  const auto reused = plan.base_reuse ? catalog.load(plan.base_reuse->id) : nullptr;
  if (reused) {
    shown = match::renderStored(*reused, *plan.base_reuse->transform, w, h);
  } else if (plan.found) {
    shown = match::renderPattern(plan.found->tile_rgb, plan.found->tile_mask, plan.found->lattice,
                                 {}, w, h);
  } else {
    return {};
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

PreparedOverlay LayerPlanner::describeOverlay(const match::TextureDescription& bitmap,
                                              const cv::Rect& box) const {
  // The whole box: an object's plain background may pass for the base's colours texel by
  // texel, yet it is the object's.
  PreparedOverlay overlay;
  overlay.box = box;
  overlay.description =
      match::describeTexture(bitmap.rgb(box).clone(), bitmap.mask(box).clone(), cascade_.config());
  const cv::Mat empty = overlay.description.mask == 0;
  if (cv::countNonZero(empty) > 0) {
    cv::inpaint(overlay.description.rgb, empty, overlay.opaque_rgb, 3.0, cv::INPAINT_TELEA);
  } else {
    overlay.opaque_rgb = overlay.description.rgb;
  }
  return overlay;
}

std::vector<OverlayMatch> LayerPlanner::matchOverlays(const match::TextureDescription& bitmap,
                                                      const std::vector<cv::Rect>& boxes) const {
  std::vector<OverlayMatch> overlays;
  for (const cv::Rect& box : boxes) {
    const PreparedOverlay* ready = nullptr;
    if (prepared_ != nullptr) {
      for (const PreparedOverlay& candidate : prepared_->overlays) {
        if (candidate.box == box) ready = &candidate;
      }
    }
    PreparedOverlay described;
    if (ready == nullptr) described = describeOverlay(bitmap, box);
    const PreparedOverlay& source = ready != nullptr ? *ready : described;
    OverlayMatch overlay;
    overlay.box = box;
    overlay.description = source.description;
    overlay.opaque_rgb = source.opaque_rgb;
    overlay.decision = cascade_.match(overlay.description, catalog_,
                                      ready != nullptr ? &ready->prechecked : nullptr);
    overlays.push_back(std::move(overlay));
  }
  return overlays;
}

PreparedLayers LayerPlanner::prepare(const match::TextureDescription& bitmap,
                                     const std::optional<pattern::Pattern>& found,
                                     const std::vector<match::CandidateVerdict>& verdicts) const {
  const auto start = std::chrono::steady_clock::now();
  // The commit's likely path only: a match needs no layers, and a pattern's plan rarely fails.
  PreparedLayers prepared;
  if (std::any_of(verdicts.begin(), verdicts.end(),
                  [](const match::CandidateVerdict& v) { return v.accepted; })) {
    return prepared;
  }
  std::vector<cv::Rect> boxes;
  if (found) {
    boxes = overlayBoxes(found->overlays, bitmap.rgb.size(), patterns_);
    // Every stored pattern the plan may try, until one is accepted, as it tries them.
    const std::optional<match::TextureDescription> base = patternBase(bitmap, boxes);
    const match::TextureDescription& rest = base ? *base : bitmap;
    for (const PatternCandidate& candidate : patternCandidates(rest)) {
      const match::CandidateVerdict verdict =
          tryStoredPattern(*found, rest, candidate, cascade_.config());
      prepared.stored_patterns.verdicts.emplace_back(candidate.texture, verdict);
      if (verdict.accepted) break;
    }
  } else if (std::optional<PartialReuse> partial = partialReuse(bitmap, verdicts)) {
    boxes = std::move(partial->boxes);
  }
  for (const cv::Rect& box : boxes) {  // overlayBoxes merged any that overlap
    PreparedOverlay overlay = describeOverlay(bitmap, box);
    overlay.prechecked = cascade_.precheck(overlay.description, catalog_);
    prepared.overlays.push_back(std::move(overlay));
  }
  prepared.ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  return prepared;
}

std::optional<match::TextureDescription> LayerPlanner::patternBase(
    const match::TextureDescription& bitmap, const std::vector<cv::Rect>& boxes) const {
  if (boxes.empty()) return std::nullopt;
  cv::Mat base_mask = bitmap.mask.clone();
  for (const cv::Rect& box : boxes) base_mask(box).setTo(0);
  return match::describeColours(bitmap.rgb, base_mask, cascade_.config());
}

std::vector<PatternCandidate> LayerPlanner::patternCandidates(
    const match::TextureDescription& rest) const {
  // The explained rest may be a pattern the database has (the other brick wall's).
  std::vector<PatternCandidate> candidates;
  for (const match::CcvNeighbour& n : catalog_.nearest(
           rest.ccv.values, cascade_.config().ccv_max_distance, cascade_.config().max_candidates)) {
    if (auto stored = catalog_.load(n.id); stored && stored->pattern) {
      candidates.push_back({std::move(stored), n.distance});
    }
  }
  return candidates;
}

std::optional<LayerPlan> LayerPlanner::planPattern(const match::TextureDescription& bitmap,
                                                   pattern::Pattern found) const {
  LayerPlan plan;
  const std::vector<cv::Rect> boxes = overlayBoxes(found.overlays, bitmap.rgb.size(), patterns_);
  plan.base = patternBase(bitmap, boxes);
  const match::TextureDescription& rest = plan.base ? *plan.base : bitmap;
  plan.base_reuse =
      reuseStoredPattern(found, rest, patternCandidates(rest), cascade_.config(),
                         prepared_ != nullptr ? &prepared_->stored_patterns : nullptr);
  plan.overlays = matchOverlays(bitmap, boxes);
  plan.found = std::move(found);
  return judged(bitmap, std::move(plan));
}

std::optional<LayerPlanner::PartialReuse> LayerPlanner::partialReuse(
    const match::TextureDescription& bitmap,
    const std::vector<match::CandidateVerdict>& verdicts) const {
  // The candidate the cascade placed over most of the bitmap and refused for its fidelity or
  // its coverage: what it leaves uncovered (the same floor seen further on) is an overlay of
  // the bitmap's own texels, so it needs to cover what the overlays may not.
  const pattern::PatternConfig& limits = patterns_.extractor;
  const match::CandidateVerdict* placed = nullptr;
  for (const match::CandidateVerdict& verdict : verdicts) {
    if (verdict.transform && verdict.coverage >= 1.0 - limits.max_overlay_share &&
        (placed == nullptr || verdict.psnr_db > placed->psnr_db)) {
      placed = &verdict;
    }
  }
  if (placed == nullptr) return std::nullopt;
  const auto stored = catalog_.load(placed->id);
  if (!stored || stored->pattern) return std::nullopt;
  const match::Rendered render =
      match::renderStored(*stored, *placed->transform, bitmap.rgb.cols, bitmap.rgb.rows);
  // Texels the render does not reach count as unexplained too; those outside the bitmap's
  // mask count nothing (the error is blurred before its threshold).
  cv::Mat error = pattern::colourError(bitmap.rgb, render.rgb);
  error.setTo(255.0f, ~render.covered & bitmap.mask);
  error.setTo(0.0f, ~bitmap.mask);
  const pattern::Overlays regions = pattern::findOverlays(
      error, bitmap.mask, {limits.overlay_sigmas, limits.min_overlay_error, limits.min_overlay_px});
  if (regions.blobs.empty() || regions.unexplained_share > limits.max_overlay_share) {
    spdlog::debug("texture {} placed at {:.1f} dB leaves {:.0f} % of a {}x{} bitmap unexplained",
                  placed->id, placed->psnr_db, 100.0 * regions.unexplained_share, bitmap.rgb.cols,
                  bitmap.rgb.rows);
    return std::nullopt;
  }
  return PartialReuse{placed, overlayBoxes(regions.blobs, bitmap.rgb.size(), patterns_)};
}

std::optional<LayerPlan> LayerPlanner::planPartialReuse(
    const match::TextureDescription& bitmap,
    const std::vector<match::CandidateVerdict>& verdicts) const {
  const std::optional<PartialReuse> partial = partialReuse(bitmap, verdicts);
  if (!partial) return std::nullopt;
  LayerPlan plan;
  plan.base_reuse = *partial->placed;
  plan.base_reuse->method += "+overlays";
  plan.overlays = matchOverlays(bitmap, partial->boxes);
  return judged(bitmap, std::move(plan));
}

std::optional<LayerPlan> LayerPlanner::judged(const match::TextureDescription& bitmap,
                                              LayerPlan plan) const {
  plan.fidelity = layeredFidelity(bitmap, plan, catalog_);
  const std::string refusal = cascade_.config().refusal(plan.fidelity);
  if (refusal.empty()) return plan;
  spdlog::debug("{} with {} overlays shows a {}x{} bitmap short of a reuse ({}): stored whole",
                plan.base_reuse ? fmt::format("texture {}", plan.base_reuse->id) : "a new pattern",
                plan.overlays.size(), bitmap.rgb.cols, bitmap.rgb.rows, refusal);
  return std::nullopt;
}

}  // namespace tessera::reuse
