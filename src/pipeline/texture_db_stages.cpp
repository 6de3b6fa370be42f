#include "tessera/pipeline/texture_db_stages.h"

#include <algorithm>
#include <set>

#include <spdlog/spdlog.h>
#include <opencv2/core.hpp>

#include "tessera/core/error.h"

namespace tessera::pipeline {

namespace {

double msSince(SteadyTime start) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
      .count();
}

// The texel mask of a bitmap: observed and inpainted texels.
cv::Mat validTexels(const texture::PatchBitmap& bitmap) {
  cv::Mat mask;
  cv::compare(bitmap.state, static_cast<int>(texture::TexelState::kEmpty), mask, cv::CMP_NE);
  return mask;
}

}  // namespace

DescribedPatch DescribeStage::process(const PatchJob& job) const {
  DescribedPatch described;
  described.sequence = job.sequence;
  described.batch = job.batch;
  described.batch_size = job.batch_size;
  described.frame_index = job.frame_index;
  described.finalized_at = job.finalized_at;
  described.retired = job.retired;
  if (job.retired) return described;
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
  if (!patterns_.enabled) return described;
  try {
    pattern::PatternAnalysis analysis = pattern::analysePattern(
        described.description->rgb, described.description->mask, patterns_.extractor);
    described.pattern_ms = analysis.ms;
    described.pattern = std::move(analysis.pattern);
  } catch (const std::exception& e) {  // then matched and stored without layers
    spdlog::warn("patch {} version {}: no pattern: {}", bitmap.id, bitmap.version, e.what());
  }
  return described;
}

CommitStage::CommitStage(db::TextureStore& store, reuse::StoreCatalog& catalog,
                         const reuse::CommitRules& rules)
    : store_(store), catalog_(catalog), rules_(rules) {}

CommitRecord CommitStage::process(DescribedPatch described) {
  ScopedStageTime time(timer_);
  CommitRecord record;
  if (!described.bitmap) return record;
  const texture::PatchBitmap& bitmap = *described.bitmap;
  record.patch_id = bitmap.id;
  record.version = bitmap.version;
  record.bitmap_ms = bitmap.build_ms;
  record.describe_ms = described.describe_ms;
  record.pattern_ms = described.pattern_ms;
  if (!described.description) return record;

  // Against every texture the patches before this one stored: the outcome does not depend on
  // the threads' timing.
  reuse::CommitPlan plan = reuse::planCommit(
      bitmap, *described.description, described.pattern, catalog_,
      [this](const std::string& key) { return store_.findByContentKey(key); }, rules_);
  record.method = plan.method;
  record.match_ms = plan.match_ms;
  record.pattern_ms += plan.layers_ms;
  record.ccv_considered = plan.ccv_considered;
  record.ccv_removed = plan.ccv_removed;
  ccv_considered_ += record.ccv_considered;
  ccv_removed_ += record.ccv_removed;
  match_timer_.add(record.match_ms + record.pattern_ms);

  db::Commit& commit = plan.commit;
  std::vector<std::int64_t> ids;
  const auto commit_start = std::chrono::steady_clock::now();
  try {
    ids = store_.commit(commit);
    store_commit_ms_.push_back(msSince(commit_start));
  } catch (const core::Error& e) {
    // The map keeps the patch's own bitmap; the database keeps every earlier commit.
    spdlog::error("patch {} version {}: not committed: {}", bitmap.id, bitmap.version, e.what());
    ++commit_failures_;
    return record;
  }
  for (std::size_t i = 0; i < plan.fresh.size(); ++i) {
    plan.fresh[i]->id = ids.at(i);
    catalog_.add(plan.fresh[i]);
    ++textures_stored_;
    patterns_stored_ += plan.fresh[i]->pattern ? 1 : 0;
  }
  for (db::TextureInstance& instance : commit.instances) {
    if (instance.texture_id < 0) {
      instance.texture_id = ids.at(static_cast<std::size_t>(-instance.texture_id - 1));
    }
    if (!texture_pixels_.count(instance.texture_id)) {
      const auto stored = catalog_.load(instance.texture_id);
      texture_pixels_[instance.texture_id] =
          stored ? stored->storedRgb().total() : bitmap.grid.texels();
    }
  }
  instances_[bitmap.id] = commit.instances;
  patch_pixels_[bitmap.id] = bitmap.grid.texels();
  record.instance = commit.instances.front();
  record.overlays.assign(commit.instances.begin() + 1, commit.instances.end());
  record.commit_latency_ms = msSince(described.finalized_at);
  commit_latencies_ms_.push_back(record.commit_latency_ms);
  return record;
}

void CommitStage::retire(int patch_id) {
  ScopedStageTime time(timer_);
  db::Commit commit;
  commit.retired.push_back({rules_.run_id, patch_id});
  const auto commit_start = std::chrono::steady_clock::now();
  try {
    store_.commit(commit);
    store_commit_ms_.push_back(msSince(commit_start));
  } catch (const core::Error& e) {
    // The database keeps an instance of a patch the map no longer has; the map is right.
    spdlog::error("patch {} (merged into another): its instances stay: {}", patch_id, e.what());
    ++commit_failures_;
  }
  instances_.erase(patch_id);
  patch_pixels_.erase(patch_id);
  ++retirements_;
}

CommitStage::Economy CommitStage::economy() const {
  Economy economy;
  std::set<std::int64_t> shown;
  for (const auto& [patch_id, layers] : instances_) {
    if (layers.empty()) continue;
    economy.textured_patches += 1;
    economy.reuses += layers.front().reused ? 1 : 0;
    economy.bytes_before += 3 * patch_pixels_.at(patch_id);
    for (const db::TextureInstance& layer : layers) {
      if (shown.insert(layer.texture_id).second) {
        economy.bytes_after += 3 * texture_pixels_.at(layer.texture_id);
      }
    }
  }
  return economy;
}

}  // namespace tessera::pipeline
