#pragma once
// The stages after texturing: each finalized patch's bitmap is built, described, searched for
// a periodic pattern and checked ahead against the database as it is then (many patches at
// once: none of it writes the database), then matched against the texture database and
// committed one patch at a time, in finalization order. Each patch is matched against every
// texture the patches before it stored (the checks ahead only save verifying a candidate
// again), so the same texture is never stored twice and the result does not depend on how
// many threads ran or how fast.
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <map>
#include <mutex>
#include <optional>
#include <set>
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
  int patch_id = 0;
  std::optional<int> retired;  // a retirement (PatchJob), nothing built
  planes::Patch::Frame plane;  // the patch's plane in the world: where its bitmap lies
  std::size_t batch = 0;
  std::size_t batch_size = 0;
  std::uint64_t frame_index = 0;
  std::optional<texture::PatchBitmap> bitmap;  // nothing when it could not be built
  std::optional<match::TextureDescription> description;
  std::optional<pattern::Pattern> pattern;  // in bitmap texels; looked for when enabled
  // The cascade's verdicts against the database as it was once described (match enabled).
  std::optional<match::PrecheckedVerdicts> prechecked;
  // The overlays the layer plans would try, described and prechecked likewise.
  std::optional<reuse::PreparedLayers> layers;
  double describe_ms = 0.0;                 // CCV and features of the new bitmap
  double pattern_ms = 0.0;                  // the autocorrelation analysis
  double cpu_ms = 0.0;                      // all of it, on the describing thread
  double queued_ms = 0.0;  // finalization to the start of its description (a thread free)
  SteadyTime finalized_at;
  SteadyTime described_at;  // its description done: from here it waits for the serial commit

  struct Batch {
    std::size_t index = 0, size = 0;
    std::uint64_t frame_index = 0;
  };
  Batch batchInfo() const { return {batch, batch_size, frame_index}; }
};

// Builds each patch's bitmap, describes it (CCV, features), looks for a periodic pattern in
// it and, given a catalog, runs the matching cascade ahead against it (the serial commit then
// takes the verdicts of candidates that have not changed meanwhile). Thread-safe: many
// patches at once.
class DescribeStage {
 public:
  DescribeStage(const texture::BitmapConfig& bitmaps, const match::MatchConfig& match,
                const pattern::PatternStageConfig& patterns,
                const match::TextureCatalog* catalog = nullptr)
      : bitmaps_(bitmaps), match_(match), patterns_(patterns), catalog_(catalog) {}
  DescribedPatch process(const PatchJob& job) const;

 private:
  DescribedPatch describe(const PatchJob& job) const;

  texture::BitmapConfig bitmaps_;
  match::MatchConfig match_;
  pattern::PatternStageConfig patterns_;
  const match::TextureCatalog* catalog_;  // thread-safe, or null: no precheck
};

// What one commit decided, for stats.jsonl.
struct CommitRecord {
  int patch_id = 0, version = 0;
  std::optional<db::TextureInstance> instance;  // nothing: no bitmap, or the commit failed
  std::vector<db::TextureInstance> overlays;    // layers 1.. drawn on top of `instance`
  std::string method;                           // reuse::CommitPlan::method
  PatchCommitFigures figures;
};

// A commit as the run's report sees it: what was decided, the batch of patches it belongs to,
// and its figures with the run's totals after it.
struct CommitMessage {
  CommitRecord record;
  DescribedPatch::Batch batch;
  MonitorCommit figures;
};

// Serial, in finalization order: plans each patch's commit against every texture stored so
// far (reuse::planCommit), stores the plan in one transaction and remembers the map's
// instances. The textures this run stored for a patch's older version (or a retired patch),
// once no instance uses them, are removed from the database and the catalog: a surface
// finalized again on every revisit does not pile up its superseded bitmaps.
class CommitStage {
 public:
  CommitStage(db::TextureStore& store, reuse::StoreCatalog& catalog,
              const reuse::CommitRules& rules);

  CommitRecord process(DescribedPatch described);
  // Patch `patch_id` was merged into another: its instances leave the database and the map.
  // A failed commit is counted and logged, as for process().
  void retire(int patch_id);
  // The instances of an earlier session whose map this run continues, each patch's newest
  // layers; `texels`: each patch's bitmap size, for the map's economy. Their rows in the
  // database (under the earlier sessions' runs) are retired when this run commits a new
  // version of the patch. Returns the patches whose textures the database no longer has
  // (a checkpoint older than their last commit): they are not adopted.
  std::vector<int> adopt(const std::map<int, std::vector<db::TextureInstance>>& earlier,
                         const std::map<int, std::size_t>& texels);

  // The newest committed instances of each patch id (its layers, 0 first).
  const std::map<int, std::vector<db::TextureInstance>>& instances() const { return instances_; }
  // A copy of instances(), safe while the committing thread commits (a checkpoint of the map).
  std::map<int, std::vector<db::TextureInstance>> instancesNow() const {
    const std::lock_guard lock(instances_mutex_);
    return instances_;
  }
  const CommitFigures& figures() const { return figures_; }
  // The map's texture economy now, over the newest bitmap of each patch committed or not (as
  // report.json's, computed at export from the files the map shows).
  reuse::Economy economy() const { return reuse::economyOf(shown_); }
  const StageTimer& timer() const { return timer_; }

 private:
  // Removes those of `superseded` the store can (TextureStore::removeUnused) from the catalog.
  void removeUnused(const std::vector<std::int64_t>& superseded);

  db::TextureStore& store_;
  reuse::StoreCatalog& catalog_;
  reuse::CommitRules rules_;
  // Adds to `commit` the retirement of an adopted patch's rows under earlier runs.
  void retireEarlierRuns(int patch_id, db::Commit& commit);

  mutable std::mutex instances_mutex_;  // instances_ changes on the committing thread
  std::map<int, std::vector<db::TextureInstance>> instances_;
  std::map<int, reuse::ShownPatch> shown_;  // each patch as the map shows it now
  // Each adopted patch's earlier runs, whose rows its next commit or retirement replaces.
  std::map<int, std::set<std::int64_t>> earlier_runs_;
  CommitFigures figures_;
  StageTimer timer_;
};

}  // namespace tessera::pipeline
