#pragma once
// The stages after texturing: each finalized patch's bitmap is built, described and searched
// for a periodic pattern (many patches at once: none of it reads the database), then matched
// against the texture database and committed one patch at a time, in finalization order. Each
// patch is matched against every texture the patches before it stored, so the same texture is
// never stored twice and the result does not depend on how many threads ran or how fast.
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "tessera/db/texture_store.h"
#include "tessera/match/match_cascade.h"
#include "tessera/pattern/pattern_config.h"
#include "tessera/pipeline/stage_timer.h"
#include "tessera/pipeline/stages.h"
#include "tessera/planes/patch_map.h"
#include "tessera/reuse/commit_plan.h"
#include "tessera/reuse/store_catalog.h"
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

// Builds each patch's bitmap, describes it (CCV, features) and looks for a periodic pattern in
// it. Thread-safe: many patches at once.
class DescribeStage {
 public:
  DescribeStage(const texture::BitmapConfig& bitmaps, const match::MatchConfig& match,
                const pattern::PatternStageConfig& patterns)
      : bitmaps_(bitmaps), match_(match), patterns_(patterns) {}
  DescribedPatch process(const PatchJob& job) const;

 private:
  texture::BitmapConfig bitmaps_;
  match::MatchConfig match_;
  pattern::PatternStageConfig patterns_;
};

// What one commit decided, for stats.jsonl.
struct CommitRecord {
  int patch_id = 0, version = 0;
  std::optional<db::TextureInstance> instance;  // nothing: no bitmap, or the commit failed
  std::vector<db::TextureInstance> overlays;    // layers 1.. drawn on top of `instance`
  std::string method;                           // reuse::CommitPlan::method
  std::size_t ccv_considered = 0, ccv_removed = 0;
  double bitmap_ms = 0.0, describe_ms = 0.0, match_ms = 0.0, pattern_ms = 0.0;
  double commit_latency_ms = 0.0;
};

// A commit as the run's report sees it: what was decided, the batch of patches it belongs to,
// and the run's totals after it.
struct CommitMessage {
  CommitRecord record;
  DescribedPatch::Batch batch;
  MonitorCommit totals;
};

// Serial, in finalization order: plans each patch's commit against every texture stored so
// far (reuse::planCommit), stores the plan in one transaction and remembers the map's
// instances.
class CommitStage {
 public:
  CommitStage(db::TextureStore& store, reuse::StoreCatalog& catalog,
              const reuse::CommitRules& rules);

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
  db::TextureStore& store_;
  reuse::StoreCatalog& catalog_;
  reuse::CommitRules rules_;
  std::map<int, std::vector<db::TextureInstance>> instances_;
  std::map<std::int64_t, std::size_t> texture_pixels_;
  std::map<int, std::size_t> patch_pixels_;  // texels of each committed patch's bitmap
  std::size_t textures_stored_ = 0, patterns_stored_ = 0, commit_failures_ = 0, retirements_ = 0;
  std::size_t ccv_considered_ = 0, ccv_removed_ = 0;
  std::vector<double> commit_latencies_ms_, store_commit_ms_;
  StageTimer match_timer_, timer_;
};

}  // namespace tessera::pipeline
