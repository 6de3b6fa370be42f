#include "tessera/pipeline/texture_db_stages.h"

#include <algorithm>

#include <spdlog/spdlog.h>
#include <opencv2/core.hpp>

#include "tessera/core/cpu_time.h"
#include "tessera/core/error.h"

namespace tessera::pipeline {

namespace {

double msSince(SteadyTime start) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
      .count();
}

// The textures `before` (a patch's layers) used that `after` (its layers now) does not.
std::vector<std::int64_t> texturesLeft(const std::vector<db::TextureInstance>& before,
                                       const std::vector<db::TextureInstance>& after) {
  std::vector<std::int64_t> left;
  for (const db::TextureInstance& old : before) {
    const bool kept = std::any_of(after.begin(), after.end(), [&](const db::TextureInstance& now) {
      return now.texture_id == old.texture_id;
    });
    if (!kept && std::find(left.begin(), left.end(), old.texture_id) == left.end()) {
      left.push_back(old.texture_id);
    }
  }
  return left;
}

// The texel mask of a bitmap: observed and inpainted texels.
cv::Mat validTexels(const texture::PatchBitmap& bitmap) {
  cv::Mat mask;
  cv::compare(bitmap.state, static_cast<int>(texture::TexelState::kEmpty), mask, cv::CMP_NE);
  return mask;
}

}  // namespace

DescribedPatch DescribeStage::process(const PatchJob& job) const {
  const double cpu_start_s = core::threadCpuSeconds();
  const double queued_ms = msSince(job.finalized_at);
  DescribedPatch described = describe(job);
  described.cpu_ms = 1e3 * (core::threadCpuSeconds() - cpu_start_s);
  described.queued_ms = queued_ms;
  described.described_at = std::chrono::steady_clock::now();
  return described;
}

DescribedPatch DescribeStage::describe(const PatchJob& job) const {
  DescribedPatch described;
  described.sequence = job.sequence;
  described.patch_id = job.retired ? *job.retired : job.patch.id;
  described.batch = job.batch;
  described.batch_size = job.batch_size;
  described.frame_index = job.frame_index;
  described.finalized_at = job.finalized_at;
  described.retired = job.retired;
  if (job.retired) return described;
  described.plane = job.patch.frame;
  try {
    described.bitmap = texture::buildBitmap(job.patch, bitmaps_);
  } catch (const std::exception& e) {  // cv::Exception, bad_alloc: this patch goes untextured
    spdlog::warn("patch {} version {}: no bitmap: {}", job.patch.id, job.patch.version, e.what());
    return described;
  }
  const texture::PatchBitmap& bitmap = *described.bitmap;
  if (!match_.enabled) {  // stored as it is: no description, no candidates
    described.description = match::TextureDescription{bitmap.image, validTexels(bitmap), {}, {}};
    return described;
  }
  try {
    const SteadyTime start = std::chrono::steady_clock::now();
    described.description = match::describeTexture(bitmap.image, validTexels(bitmap), match_);
    described.describe_ms = msSince(start);
  } catch (const std::exception& e) {  // one patch's failure costs its matching, not the run
    spdlog::warn("patch {} version {}: not matched: {}", bitmap.id, bitmap.version, e.what());
    return described;
  }
  if (catalog_ != nullptr && match_.precheck) {
    try {
      described.prechecked =
          match::MatchCascade(match_).precheck(*described.description, *catalog_);
    } catch (const std::exception& e) {  // the commit then verifies every candidate itself
      spdlog::debug("patch {} version {}: no precheck: {}", bitmap.id, bitmap.version, e.what());
    }
  }
  if (!patterns_.enabled) return described;
  try {
    pattern::PatternAnalysis analysis = pattern::analysePattern(
        described.description->rgb, described.description->mask, patterns_.extractor);
    described.pattern_ms = analysis.ms;
    if (analysis.pattern && !analysis.pattern->shading.empty()) {
      // The store and the exports carry a tile, not its shading: such a pattern would show
      // the light's fall-off flattened, so the patch is stored whole.
      spdlog::info(
          "patch {} version {}: periodic under light varying by {:.0f} %; stored whole (shaded "
          "patterns are not stored yet)",
          bitmap.id, bitmap.version, 100.0 * analysis.pattern->shading_spread);
    } else {
      described.pattern = std::move(analysis.pattern);
    }
  } catch (const std::exception& e) {  // then matched and stored without layers
    spdlog::warn("patch {} version {}: no pattern: {}", bitmap.id, bitmap.version, e.what());
  }
  if (described.prechecked) {
    try {
      std::vector<match::CandidateVerdict> verdicts;
      for (const auto& entry : described.prechecked->verdicts) verdicts.push_back(entry.second);
      const match::MatchCascade cascade(match_);
      described.layers = reuse::LayerPlanner(cascade, *catalog_, patterns_)
                             .prepare(*described.description, described.pattern, verdicts);
    } catch (const std::exception& e) {  // the commit then plans the layers itself
      spdlog::debug("patch {} version {}: layers not prepared: {}", bitmap.id, bitmap.version,
                    e.what());
    }
  }
  return described;
}

CommitStage::CommitStage(db::TextureStore& store, reuse::StoreCatalog& catalog,
                         const reuse::CommitRules& rules)
    : store_(store), catalog_(catalog), rules_(rules) {}

CommitRecord CommitStage::process(DescribedPatch described) {
  ScopedStageTime time(timer_);
  const double commit_queued_ms = msSince(described.described_at);
  CommitRecord record;
  if (!described.bitmap) {  // the map shows the patch no more: its bitmap is not current
    shown_.erase(described.patch_id);
    return record;
  }
  const texture::PatchBitmap& bitmap = *described.bitmap;
  record.patch_id = bitmap.id;
  record.version = bitmap.version;
  PatchCommitFigures& figures = record.figures;
  figures.bitmap_ms = bitmap.build_ms;
  figures.describe_ms = described.describe_ms;
  figures.pattern_ms = described.pattern_ms;
  figures.describe_queued_ms = described.queued_ms;
  figures.commit_queued_ms = commit_queued_ms;
  figures_.describe.add(figures.bitmap_ms + figures.describe_ms + figures.pattern_ms,
                        described.cpu_ms);
  // Until it is committed, the map shows the patch's own bitmap.
  shown_[bitmap.id] = reuse::ShownPatch{bitmap.grid.texels(), {}};
  if (!described.description) return record;

  // Against every texture the patches before this one stored: the outcome does not depend on
  // the threads' timing.
  const match::PrecheckedVerdicts* prechecked =
      described.prechecked ? &*described.prechecked : nullptr;
  figures.precheck_ms = (prechecked != nullptr ? prechecked->ms : 0.0) +
                        (described.layers ? described.layers->ms : 0.0);
  reuse::CommitPlan plan = reuse::planCommit(
      bitmap, *described.description, described.pattern, catalog_,
      [this](const std::string& key) { return store_.findByContentKey(key); }, rules_, prechecked,
      described.layers ? &*described.layers : nullptr);
  record.method = plan.method;
  figures.match_ms = plan.match_ms;
  figures.pattern_ms += plan.layers_ms;
  figures.ccv_considered = plan.ccv_considered;
  figures.ccv_removed = plan.ccv_removed;
  figures_.ccv_considered += figures.ccv_considered;
  figures_.ccv_removed += figures.ccv_removed;
  figures_.match.add(figures.match_ms + figures.pattern_ms);

  db::Commit& commit = plan.commit;
  retireEarlierRuns(bitmap.id, commit);
  std::vector<std::int64_t> ids;
  const auto commit_start = std::chrono::steady_clock::now();
  try {
    ids = store_.commit(commit);
    figures_.store_commit_ms.add(msSince(commit_start));
  } catch (const core::Error& e) {
    // The map keeps the patch's own bitmap; the database keeps every earlier commit.
    spdlog::error("patch {} version {}: not committed: {}", bitmap.id, bitmap.version, e.what());
    ++figures_.commit_failures;
    return record;
  }
  for (std::size_t i = 0; i < plan.fresh.size(); ++i) {
    plan.fresh[i]->id = ids.at(i);
    catalog_.add(plan.fresh[i]);
    ++figures_.textures_stored;
    figures_.patterns_stored += plan.fresh[i]->pattern ? 1 : 0;
  }
  for (db::TextureInstance& instance : commit.instances) {
    if (instance.texture_id < 0) {
      instance.texture_id = ids.at(static_cast<std::size_t>(-instance.texture_id - 1));
    }
  }
  std::vector<std::int64_t> superseded;
  {
    const std::lock_guard lock(instances_mutex_);
    std::vector<db::TextureInstance>& stored = instances_[bitmap.id];
    superseded = texturesLeft(stored, commit.instances);
    stored = commit.instances;
  }
  removeUnused(superseded);
  shown_[bitmap.id] = reuse::shownPatch(bitmap.grid.texels(), commit.instances,
                                        catalog_.loadLayers(commit.instances));
  record.instance = commit.instances.front();
  record.overlays.assign(commit.instances.begin() + 1, commit.instances.end());
  figures.commit_latency_ms = msSince(described.finalized_at);
  figures_.commit_latencies_ms.add(figures.commit_latency_ms);
  figures_.describe_queued_ms.add(figures.describe_queued_ms);
  figures_.commit_queued_ms.add(figures.commit_queued_ms);
  return record;
}

std::vector<int> CommitStage::adopt(const std::map<int, std::vector<db::TextureInstance>>& earlier,
                                    const std::map<int, std::size_t>& texels) {
  std::vector<int> missing;
  for (const auto& [patch_id, layers] : earlier) {
    for (const db::TextureInstance& layer : layers) earlier_runs_[patch_id].insert(layer.run_id);
    const auto size = texels.find(patch_id);
    if (layers.empty() || size == texels.end()) continue;
    const auto stored = catalog_.loadLayers(layers);
    if (stored.empty()) {
      missing.push_back(patch_id);
      continue;
    }
    const std::lock_guard lock(instances_mutex_);
    instances_[patch_id] = layers;
    shown_[patch_id] = reuse::shownPatch(size->second, layers, stored);
  }
  return missing;
}

void CommitStage::retireEarlierRuns(int patch_id, db::Commit& commit) {
  const auto runs = earlier_runs_.find(patch_id);
  if (runs == earlier_runs_.end()) return;
  for (const std::int64_t run : runs->second) {
    if (run != rules_.run_id) commit.retired.push_back({run, patch_id});  // again: a no-op
  }
}

void CommitStage::retire(int patch_id) {
  ScopedStageTime time(timer_);
  db::Commit commit;
  commit.retired.push_back({rules_.run_id, patch_id});
  retireEarlierRuns(patch_id, commit);
  const auto commit_start = std::chrono::steady_clock::now();
  try {
    store_.commit(commit);
    figures_.store_commit_ms.add(msSince(commit_start));
    if (const auto it = instances_.find(patch_id); it != instances_.end()) {
      removeUnused(texturesLeft(it->second, {}));
    }
  } catch (const core::Error& e) {
    // The database keeps an instance of a patch the map no longer has; the map is right.
    spdlog::error("patch {} (merged into another): its instances stay: {}", patch_id, e.what());
    ++figures_.commit_failures;
  }
  {
    const std::lock_guard lock(instances_mutex_);
    instances_.erase(patch_id);
  }
  shown_.erase(patch_id);
  ++figures_.retirements;
}

void CommitStage::removeUnused(const std::vector<std::int64_t>& superseded) {
  if (superseded.empty()) return;
  try {
    for (const std::int64_t id : store_.removeUnused(rules_.run_id, superseded)) {
      catalog_.remove(id);
      ++figures_.textures_removed;
    }
  } catch (const core::Error& e) {  // they stay stored, unused: space, not correctness
    spdlog::warn("superseded textures not removed: {}", e.what());
  }
}

}  // namespace tessera::pipeline
