#pragma once
// The stages after texturing: each finalized patch's bitmap is built, described and searched
// for a periodic pattern (many patches at once: none of it reads the database), then matched
// against the texture database and committed one patch at a time, in finalization order. Each
// patch is matched against every texture the patches before it stored, so the same texture is
// never stored twice and the result does not depend on how many threads ran or how fast.
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <list>
#include <map>
#include <memory>
#include <optional>
#include <vector>

#include "tessera/db/texture_store.h"
#include "tessera/match/match_cascade.h"
#include "tessera/pattern/pattern_config.h"
#include "tessera/pipeline/stage_timer.h"
#include "tessera/pipeline/stages.h"
#include "tessera/planes/patch_map.h"
#include "tessera/texture/bitmap_builder.h"

namespace tessera::pipeline {

using SteadyTime = std::chrono::steady_clock::time_point;

// A patch the plane stage finalized, numbered in finalization order; `batch` groups the
// patches finalized by one frame (or by the end of the stream).
// A retirement (`retired`: the patch was merged into another) takes a place in the same
// order, so that it reaches the database after every commit of the patch before it.
struct PatchJob {
  std::size_t sequence = 0;
  std::size_t batch = 0;
  std::size_t batch_size = 0;
  std::uint64_t frame_index = 0;
  planes::PatchSnapshot patch;
  SteadyTime finalized_at;
  std::optional<int> retired;  // the patch id; `patch` and the batch are then unused
};

// A region of a bitmap that its base layer does not explain (a poster on a brick wall),
// matched like any bitmap: drawn on top of the base from a texture it reuses, or from its own
// crop.
struct OverlayMatch {
  cv::Rect box;                           // in bitmap texels
  match::TextureDescription description;  // the crop, with the bitmap's mask
  // The crop as stored: its empty texels inpainted, so that the overlay hides the base over
  // its whole box (the base would show another surface through them).
  cv::Mat opaque_rgb;
  match::MatchDecision decision;  // the crop's texel -> a stored texture, if any
};

// A bitmap that matched nothing, shown in layers: a base (a new periodic pattern, or a
// stored texture that shows all but some regions of it) with those regions as overlays.
struct LayerPlan {
  std::optional<pattern::Pattern> found;  // a new pattern, in bitmap texels
  // The bitmap without its overlay regions (when there are some), and a stored texture that
  // shows it (then reused instead of the new pattern; always there without one).
  std::optional<match::TextureDescription> base;
  std::optional<match::CandidateVerdict> base_reuse;
  std::vector<OverlayMatch> overlays;
  match::Fidelity fidelity;  // of all layers together, over the whole bitmap
};

// A patch's bitmap, its description and the periodic pattern in it: all that can be worked
// out without the database.
struct DescribedPatch {
  std::size_t sequence = 0;
  std::optional<int> retired;  // a retirement (PatchJob), nothing built
  std::size_t batch = 0;
  std::size_t batch_size = 0;
  std::uint64_t frame_index = 0;
  std::optional<texture::PatchBitmap> bitmap;  // nothing when it could not be built
  std::optional<match::TextureDescription> description;
  std::optional<pattern::Pattern> pattern;  // in bitmap texels; looked for when enabled
  double describe_ms = 0.0;                 // CCV and features of the new bitmap
  double pattern_ms = 0.0;                  // the autocorrelation analysis
  SteadyTime finalized_at;

  struct Batch {
    std::size_t index = 0, size = 0;
    std::uint64_t frame_index = 0;
  };
  Batch batchInfo() const { return {batch, batch_size, frame_index}; }
};

// The texel mask of a bitmap: observed and inpainted texels.
cv::Mat validTexels(const texture::PatchBitmap& bitmap);

// The database's textures as the cascade sees them: their CCVs in an index, the textures
// themselves loaded on demand (and kept). Read and written by the commit stage only.
class StoreCatalog : public match::TextureCatalog {
 public:
  StoreCatalog(const db::TextureStore& store, const match::MatchConfig& config);

  std::size_t size() const override { return size_; }
  std::vector<match::CcvNeighbour> nearest(const std::vector<float>& ccv, double max_distance,
                                           std::size_t k) const override;
  std::shared_ptr<const match::StoredTexture> load(std::int64_t id) const override;

  // After a commit.
  void add(std::shared_ptr<const match::StoredTexture> texture);
  // Bytes of the textures held in memory now (at most MatchConfig::catalog_cache_mb, or one).
  std::size_t cachedBytes() const { return cached_bytes_; }

 private:
  // Holds `texture` as the most recently used, dropping the least recently used beyond the
  // budget (never the one just held).
  void hold(std::shared_ptr<const match::StoredTexture> texture) const;

  struct Cached {
    std::shared_ptr<const match::StoredTexture> texture;
    std::size_t bytes = 0;
    std::list<std::int64_t>::iterator recency;
  };
  const db::TextureStore& store_;
  match::MatchConfig config_;
  match::CcvIndex index_;
  std::size_t size_ = 0;
  mutable std::map<std::int64_t, Cached> cache_;
  mutable std::list<std::int64_t> recency_;  // most recently used first
  mutable std::size_t cached_bytes_ = 0;
};

// A database record as the cascade sees it; features are recomputed when the record's were
// made by another detector.
std::shared_ptr<const match::StoredTexture> storedTextureOf(const db::TextureRecord& record,
                                                            const match::MatchConfig& config);

// Plans a bitmap's layers against the catalog as it is (layer_plan.cpp).
class LayerPlanner {
 public:
  LayerPlanner(const match::MatchCascade& cascade, const StoreCatalog& catalog,
               const pattern::PatternStageConfig& patterns)
      : cascade_(cascade), catalog_(catalog), patterns_(patterns) {}
  const pattern::PatternStageConfig& config() const { return patterns_; }

  // A periodic pattern found in the bitmap: its base (a stored pattern the explained part
  // reuses, else the new tile) and its overlays.
  std::optional<LayerPlan> planPattern(const match::TextureDescription& bitmap,
                                       pattern::Pattern found) const;
  // The candidate that covers most of the bitmap, best first among `verdicts` (placed but
  // refused for fidelity), as the base, and what it does not explain as overlays.
  std::optional<LayerPlan> planPartialReuse(
      const match::TextureDescription& bitmap,
      const std::vector<match::CandidateVerdict>& verdicts) const;

 private:
  std::vector<OverlayMatch> matchOverlays(const match::TextureDescription& bitmap,
                                          const std::vector<cv::Rect>& boxes) const;
  std::optional<LayerPlan> judged(const match::TextureDescription& bitmap, LayerPlan plan) const;

  const match::MatchCascade& cascade_;
  const StoreCatalog& catalog_;
  pattern::PatternStageConfig patterns_;
};

// Builds each patch's bitmap, describes it (CCV, features) and looks for a periodic pattern in
// it. Thread-safe: many patches at once.
class DescribeStage {
 public:
  DescribeStage(const TextureStage& textures, const match::MatchConfig& match,
                const pattern::PatternStageConfig& patterns)
      : textures_(textures), match_(match), patterns_(patterns) {}
  DescribedPatch process(const PatchJob& job) const;

 private:
  const TextureStage& textures_;
  match::MatchConfig match_;
  pattern::PatternStageConfig patterns_;
};

// A stored pattern the cascade's prefilter let through, with its CCV distance.
struct PatternCandidate {
  std::shared_ptr<const match::StoredTexture> texture;
  double ccv_distance = 0.0;
};

// The first candidate that shows `shown` (a bitmap, or the part its overlays leave) as
// faithfully as a reuse must, aligned to `found` through the two lattices (match/
// pattern_alignment.h): two walls of the same bricks share one tile even when their texel
// grids are turned against each other.
std::optional<match::CandidateVerdict> reuseStoredPattern(
    const pattern::Pattern& found, const match::TextureDescription& shown,
    const std::vector<PatternCandidate>& candidates, const match::MatchConfig& config);

// Patch texel -> texel of the crop `box` (an overlay's own texture).
core::Similarity2 patchToBox(const cv::Rect& box);

// How faithfully a plan's layers (the new pattern or the stored texture `base_reuse` names,
// then the overlays, each a reuse or its own crop) show `bitmap`; stored textures from
// `catalog`.
match::Fidelity layeredFidelity(const match::TextureDescription& bitmap, const LayerPlan& plan,
                                const match::TextureCatalog& catalog);

// What one commit decided, for stats.jsonl.
struct CommitRecord {
  int patch_id = 0, version = 0;
  std::optional<db::TextureInstance> instance;  // nothing: no bitmap, or the commit failed
  std::vector<db::TextureInstance> overlays;    // layers 1.. drawn on top of `instance`
  // "ncc", "features", "same pixels", "stored" or "pattern"
  std::string method;
  std::size_t ccv_considered = 0, ccv_removed = 0;
  double bitmap_ms = 0.0, describe_ms = 0.0, match_ms = 0.0, pattern_ms = 0.0;
  double commit_latency_ms = 0.0;
};

// Serial, in finalization order: match against every texture stored so far (a bitmap that
// matches nothing is planned in layers: its periodic pattern, or a stored texture with some
// regions changed), store, and remember the map's instances.
class CommitStage {
 public:
  CommitStage(db::TextureStore& store, StoreCatalog& catalog, const match::MatchCascade& cascade,
              const pattern::PatternStageConfig& patterns, std::int64_t run_id);

  CommitRecord process(DescribedPatch described);
  // Patch `patch_id` was merged into another: its instances leave the database and the map.
  // A failed commit is counted and logged, as for process().
  void retire(int patch_id);
  std::size_t retirements() const { return retirements_; }

  // The newest instances of each patch id (its layers, 0 first), and the textures they use
  // (pixels per texture).
  const std::map<int, std::vector<db::TextureInstance>>& instances() const { return instances_; }
  const std::map<std::int64_t, std::size_t>& texturePixels() const { return texture_pixels_; }
  std::size_t texturesStored() const { return textures_stored_; }
  std::size_t patternsStored() const { return patterns_stored_; }
  // The map's committed patches now: how many, how many reuse a texture, their bitmaps' bytes
  // and the bytes of the distinct textures they show (layers included). The live counterpart
  // of report.json's economy, which also counts bitmaps never committed.
  struct Economy {
    std::size_t textured_patches = 0, reuses = 0, bytes_before = 0, bytes_after = 0;
  };
  Economy economy() const;
  std::size_t commitFailures() const { return commit_failures_; }
  std::size_t ccvConsidered() const { return ccv_considered_; }
  std::size_t ccvRemoved() const { return ccv_removed_; }
  const std::vector<double>& commitLatenciesMs() const { return commit_latencies_ms_; }
  // The database's own share: each TextureStore::commit call (retirements included).
  const std::vector<double>& storeCommitMs() const { return store_commit_ms_; }
  const StageTimer& matchTimer() const { return match_timer_; }
  const StageTimer& timer() const { return timer_; }

 private:
  // A bitmap that matched nothing: its layers, when together they show it as faithfully as a
  // reuse must (then stored instead of the bitmap). Adds the planning time to `record`.
  std::optional<LayerPlan> planLayers(const DescribedPatch& described,
                                      const match::MatchDecision& decision,
                                      CommitRecord& record) const;
  // A layer plan's textures and instances (layer 0 the base, then the overlays) into
  // `commit`; new textures' descriptions into `fresh` (parallel to commit.textures).
  void planCommit(const texture::PatchBitmap& bitmap, const LayerPlan& plan, db::Commit& commit,
                  std::vector<std::shared_ptr<match::StoredTexture>>& fresh,
                  CommitRecord& record) const;
  // A new texture for `commit`, or the id of one with the same pixels already stored
  // (negative: index into commit.textures, as db::Commit counts them).
  std::int64_t addTexture(db::TextureRecord texture,
                          std::shared_ptr<match::StoredTexture> described, db::Commit& commit,
                          std::vector<std::shared_ptr<match::StoredTexture>>& fresh) const;

  db::TextureStore& store_;
  StoreCatalog& catalog_;
  const match::MatchCascade& cascade_;
  LayerPlanner planner_;
  std::int64_t run_id_;
  std::map<int, std::vector<db::TextureInstance>> instances_;
  std::map<std::int64_t, std::size_t> texture_pixels_;
  std::map<int, std::size_t> patch_pixels_;  // texels of each committed patch's bitmap
  std::size_t textures_stored_ = 0, patterns_stored_ = 0, commit_failures_ = 0, retirements_ = 0;
  std::size_t ccv_considered_ = 0, ccv_removed_ = 0;
  std::vector<double> commit_latencies_ms_, store_commit_ms_;
  StageTimer match_timer_, timer_;
};

}  // namespace tessera::pipeline
