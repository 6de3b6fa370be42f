#pragma once
// Layers for a bitmap that matched nothing whole. Its base is a periodic pattern (new, or a
// stored one aligned through the two lattices) or a stored texture the cascade placed but
// refused because some regions differ (a blackboard on one wall, posters on the other) or it
// covers only part of the bitmap (the same floor seen further on: the rest is an overlay).
// Regions the base does not explain become overlays, matched against the catalog like any
// bitmap. A plan is kept only when all its layers together pass MatchConfig::accepts.
#include <optional>
#include <vector>

#include <opencv2/core/types.hpp>

#include "tessera/core/similarity2.h"
#include "tessera/match/match_cascade.h"
#include "tessera/pattern/pattern_config.h"

namespace tessera::reuse {

// A region of a bitmap that its base layer does not explain (a poster on a brick wall), drawn
// on top of the base from a texture it reuses, or from its own crop.
struct OverlayMatch {
  cv::Rect box;                           // in bitmap texels
  match::TextureDescription description;  // the crop, with the bitmap's mask
  // The crop as stored: its empty texels inpainted, so that the overlay hides the base over
  // its whole box (the base would show another surface through them).
  cv::Mat opaque_rgb;
  match::MatchDecision decision;  // the crop's texel -> a stored texture, if any
};

// An overlay crop worked out ahead of the serial commit, on the describing threads: what
// depends on the bitmap and the box only (the description and the inpainted crop), and the
// cascade's verdicts against the catalog as it was then.
struct PreparedOverlay {
  cv::Rect box;
  match::TextureDescription description;
  cv::Mat opaque_rgb;
  match::PrecheckedVerdicts prechecked;
};

struct PreparedLayers {
  std::vector<PreparedOverlay> overlays;
  // A found pattern's verdicts against the stored patterns it may reuse.
  match::PrecheckedVerdicts stored_patterns;
  double ms = 0.0;
};

struct LayerPlan {
  std::optional<pattern::Pattern> found;  // a new pattern, in bitmap texels
  // The bitmap without its overlay regions (when there are some; its CCV, no features), and
  // a stored texture that shows it (then reused instead of the new pattern; always there
  // without one).
  std::optional<match::TextureDescription> base;
  std::optional<match::CandidateVerdict> base_reuse;
  std::vector<OverlayMatch> overlays;
  match::Fidelity fidelity;  // of all layers together, over the whole bitmap
};

// A stored pattern the cascade's prefilter let through, with its CCV distance.
struct PatternCandidate {
  std::shared_ptr<const match::StoredTexture> texture;
  double ccv_distance = 0.0;
};

// Plans a bitmap's layers against a catalog as it is. Overlays `prepared` holds for the same
// box take its description and verdicts: the plan is the same as without them.
class LayerPlanner {
 public:
  LayerPlanner(const match::MatchCascade& cascade, const match::TextureCatalog& catalog,
               const pattern::PatternStageConfig& patterns,
               const PreparedLayers* prepared = nullptr)
      : cascade_(cascade), catalog_(catalog), patterns_(patterns), prepared_(prepared) {}

  // Ahead of the commit, when none of the cascade's verdicts against the catalog now was
  // accepted: the overlays the plan would most likely try (the pattern's when one was found,
  // else a partial reuse's), described and prechecked, and the pattern's verdicts against the
  // stored patterns.
  PreparedLayers prepare(const match::TextureDescription& bitmap,
                         const std::optional<pattern::Pattern>& found,
                         const std::vector<match::CandidateVerdict>& verdicts) const;

  // A periodic pattern found in the bitmap: its base (a stored pattern the explained part
  // reuses, else the new tile) and its overlays.
  std::optional<LayerPlan> planPattern(const match::TextureDescription& bitmap,
                                       pattern::Pattern found) const;
  // The best placed candidate among `verdicts` (refused for fidelity or coverage) that covers
  // at least 1 - max_overlay_share of the bitmap, as the base, and what it does not explain or
  // cover as overlays.
  std::optional<LayerPlan> planPartialReuse(
      const match::TextureDescription& bitmap,
      const std::vector<match::CandidateVerdict>& verdicts) const;

 private:
  // What the placed candidate among `verdicts` leaves unexplained, as overlay boxes; nothing
  // when no candidate is placed well enough for a partial reuse.
  struct PartialReuse {
    const match::CandidateVerdict* placed = nullptr;
    std::vector<cv::Rect> boxes;
  };
  // A found pattern's base: the bitmap without its overlays' boxes (nothing when none).
  std::optional<match::TextureDescription> patternBase(const match::TextureDescription& bitmap,
                                                       const std::vector<cv::Rect>& boxes) const;
  std::vector<PatternCandidate> patternCandidates(const match::TextureDescription& rest) const;
  std::optional<PartialReuse> partialReuse(
      const match::TextureDescription& bitmap,
      const std::vector<match::CandidateVerdict>& verdicts) const;
  PreparedOverlay describeOverlay(const match::TextureDescription& bitmap,
                                  const cv::Rect& box) const;
  std::vector<OverlayMatch> matchOverlays(const match::TextureDescription& bitmap,
                                          const std::vector<cv::Rect>& boxes) const;
  std::optional<LayerPlan> judged(const match::TextureDescription& bitmap, LayerPlan plan) const;

  const match::MatchCascade& cascade_;
  const match::TextureCatalog& catalog_;
  pattern::PatternStageConfig patterns_;
  const PreparedLayers* prepared_;
};

// `candidate` aligned to `found` through the two lattices (match/pattern_alignment.h), and
// how faithfully it then shows `shown` (a bitmap, or the part its overlays leave): two walls
// of the same bricks share one tile even when their texel grids are turned against each other.
match::CandidateVerdict tryStoredPattern(const pattern::Pattern& found,
                                         const match::TextureDescription& shown,
                                         const PatternCandidate& candidate,
                                         const match::MatchConfig& config);

// The first of `candidates` that shows `shown` as faithfully as a reuse must. A candidate
// `prechecked` holds a verdict for (the very same stored texture) takes it as it is.
std::optional<match::CandidateVerdict> reuseStoredPattern(
    const pattern::Pattern& found, const match::TextureDescription& shown,
    const std::vector<PatternCandidate>& candidates, const match::MatchConfig& config,
    const match::PrecheckedVerdicts* prechecked = nullptr);

// Patch texel -> texel of the crop `box` (an overlay's own texture).
core::Similarity2 patchToBox(const cv::Rect& box);

// How faithfully a plan's layers (the new pattern or the stored texture `base_reuse` names,
// then the overlays, each a reuse or its own crop) show `bitmap`; stored textures from
// `catalog`.
match::Fidelity layeredFidelity(const match::TextureDescription& bitmap, const LayerPlan& plan,
                                const match::TextureCatalog& catalog);

}  // namespace tessera::reuse
