#include "tessera/pipeline/texture_db_stages.h"

#include <algorithm>
#include <set>

#include <spdlog/spdlog.h>
#include <opencv2/core.hpp>

#include "tessera/core/error.h"
#include "tessera/match/ccv.h"

namespace tessera::pipeline {

namespace {

double msSince(SteadyTime start) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
      .count();
}

}  // namespace

cv::Mat validTexels(const texture::PatchBitmap& bitmap) {
  cv::Mat mask;
  cv::compare(bitmap.state, static_cast<int>(texture::TexelState::kEmpty), mask, cv::CMP_NE);
  return mask;
}

std::shared_ptr<const match::StoredTexture> storedTextureOf(const db::TextureRecord& record,
                                                            const match::MatchConfig& config) {
  if (record.kind == db::TextureKind::kPattern) {
    // Without a lattice (never written so), the image is one period in each direction.
    const core::Lattice2 cell =
        record.lattice.value_or(core::Lattice2{{record.rgb.cols, 0.0}, {0.0, record.rgb.rows}});
    return match::patternTexture(record.id, record.rgb, record.mask, cell, config);
  }
  auto stored = std::make_shared<match::StoredTexture>();
  stored->id = record.id;
  match::TextureDescription& description = stored->description;
  description.rgb = record.rgb;
  description.mask = record.mask;
  description.ccv.values = record.ccv;
  description.ccv.pixels = static_cast<std::size_t>(cv::countNonZero(record.mask));
  if (record.ccv.size() != match::ccvLength(config.ccv)) {  // stored under other CCV settings
    description.ccv = match::computeCcv(record.rgb, record.mask, config.ccv);
  }
  if (record.feature_kind == config.features.detector) {
    description.features = {record.feature_kind, record.keypoints, record.descriptors};
  } else {
    description.features = match::detectFeatures(record.rgb, record.mask, config.features);
  }
  return stored;
}

StoreCatalog::StoreCatalog(const db::TextureStore& store, const match::MatchConfig& config)
    : store_(store), config_(config), index_(match::ccvLength(config.ccv)) {
  const std::size_t dims = match::ccvLength(config.ccv);
  for (const db::CcvEntry& entry : store.ccvVectors()) {
    if (entry.ccv.size() == dims) {
      index_.add(entry.id, entry.ccv);
    } else if (const auto record = store.texture(entry.id)) {  // stored under other settings
      index_.add(entry.id, match::computeCcv(record->rgb, record->mask, config.ccv).values);
    }
    ++size_;
  }
}

std::vector<match::CcvNeighbour> StoreCatalog::nearest(const std::vector<float>& ccv,
                                                       double max_distance, std::size_t k) const {
  return index_.query(ccv, max_distance, k);
}

namespace {

std::size_t bytesOf(const cv::Mat& m) { return m.total() * m.elemSize(); }

std::size_t bytesOf(const match::StoredTexture& t) {
  return bytesOf(t.description.rgb) + bytesOf(t.description.mask) +
         bytesOf(t.description.features.descriptors) +
         t.description.features.keypoints.size() * sizeof(cv::KeyPoint) + bytesOf(t.tile_rgb) +
         bytesOf(t.tile_mask) + t.description.ccv.values.size() * sizeof(float);
}

}  // namespace

void StoreCatalog::hold(std::shared_ptr<const match::StoredTexture> texture) const {
  const std::int64_t id = texture->id;
  if (const auto it = cache_.find(id); it != cache_.end()) {
    cached_bytes_ -= it->second.bytes;
    recency_.erase(it->second.recency);
    cache_.erase(it);
  }
  recency_.push_front(id);
  const std::size_t bytes = bytesOf(*texture);
  cache_[id] = {std::move(texture), bytes, recency_.begin()};
  cached_bytes_ += bytes;
  const auto budget = static_cast<std::size_t>(config_.catalog_cache_mb * 1e6);
  while (cached_bytes_ > budget && recency_.size() > 1) {
    const auto gone = cache_.find(recency_.back());
    cached_bytes_ -= gone->second.bytes;
    cache_.erase(gone);
    recency_.pop_back();
  }
}

std::shared_ptr<const match::StoredTexture> StoreCatalog::load(std::int64_t id) const {
  if (const auto it = cache_.find(id); it != cache_.end()) {
    recency_.splice(recency_.begin(), recency_, it->second.recency);
    return it->second.texture;
  }
  const std::optional<db::TextureRecord> record = store_.texture(id);
  if (!record) return nullptr;
  std::shared_ptr<const match::StoredTexture> texture = storedTextureOf(*record, config_);
  hold(texture);
  return texture;
}

void StoreCatalog::add(std::shared_ptr<const match::StoredTexture> texture) {
  // Undescribed (match.enabled false): kept for export, never a candidate.
  if (!texture->description.ccv.values.empty()) {
    index_.add(texture->id, texture->description.ccv.values);
    ++size_;
  }
  hold(std::move(texture));
}

DescribedPatch DescribeStage::process(const PatchJob& job) const {
  DescribedPatch described;
  described.sequence = job.sequence;
  described.batch = job.batch;
  described.batch_size = job.batch_size;
  described.frame_index = job.frame_index;
  described.finalized_at = job.finalized_at;
  described.retired = job.retired;
  if (job.retired) return described;
  described.bitmap = textures_.build(job.patch);
  if (!described.bitmap) return described;
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

CommitStage::CommitStage(db::TextureStore& store, StoreCatalog& catalog,
                         const match::MatchCascade& cascade,
                         const pattern::PatternStageConfig& patterns, std::int64_t run_id)
    : store_(store),
      catalog_(catalog),
      cascade_(cascade),
      planner_(cascade, catalog, patterns),
      run_id_(run_id) {}

std::optional<LayerPlan> CommitStage::planLayers(const DescribedPatch& described,
                                                 const match::MatchDecision& decision,
                                                 CommitRecord& record) const {
  const SteadyTime start = std::chrono::steady_clock::now();
  std::optional<LayerPlan> plan;
  try {
    if (described.pattern) plan = planner_.planPattern(*described.description, *described.pattern);
    // A bitmap that nothing shows whole may be a stored texture with some regions changed (the
    // same plaster, another poster on it).
    if (!plan) plan = planner_.planPartialReuse(*described.description, decision.verdicts);
  } catch (const std::exception& e) {  // then stored whole
    const texture::PatchBitmap& bitmap = *described.bitmap;
    spdlog::warn("patch {} version {}: no layers: {}", bitmap.id, bitmap.version, e.what());
    plan.reset();
  }
  record.pattern_ms += msSince(start);
  return plan;
}

std::int64_t CommitStage::addTexture(
    db::TextureRecord texture, std::shared_ptr<match::StoredTexture> described, db::Commit& commit,
    std::vector<std::shared_ptr<match::StoredTexture>>& fresh) const {
  texture.content_key = db::contentKey(texture.rgb, texture.mask);
  texture.run_id = run_id_;
  // The very same pixels already stored (a rerun of a recording): that texture, as it is.
  if (const auto existing = store_.findByContentKey(texture.content_key)) return *existing;
  for (std::size_t i = 0; i < commit.textures.size(); ++i) {
    if (commit.textures[i].content_key == texture.content_key) {
      return -static_cast<std::int64_t>(i) - 1;
    }
  }
  commit.textures.push_back(std::move(texture));
  fresh.push_back(std::move(described));
  return -static_cast<std::int64_t>(commit.textures.size());
}

namespace {

// A bitmap's pixels, description and features as a single texture record.
db::TextureRecord singleRecord(const match::TextureDescription& description, double texel_m,
                               int source_patch) {
  db::TextureRecord texture;
  texture.kind = db::TextureKind::kSingle;
  texture.rgb = description.rgb;
  texture.mask = description.mask;
  texture.texel_m = texel_m;
  texture.ccv = description.ccv.values;
  texture.feature_kind = description.features.kind;
  texture.keypoints = description.features.keypoints;
  texture.descriptors = description.features.descriptors;
  texture.source_patch = source_patch;
  return texture;
}

}  // namespace

void CommitStage::planCommit(const texture::PatchBitmap& bitmap, const LayerPlan& plan,
                             db::Commit& commit,
                             std::vector<std::shared_ptr<match::StoredTexture>>& fresh,
                             CommitRecord& record) const {
  db::TextureInstance base;
  base.run_id = run_id_;
  base.patch_id = bitmap.id;
  base.version = bitmap.version;
  base.psnr_db = plan.fidelity.psnr_db;
  if (plan.base_reuse) {
    base.texture_id = plan.base_reuse->id;
    base.transform = *plan.base_reuse->transform;
    base.reused = true;
    record.method = plan.base_reuse->method;
  } else {  // one cell of the pattern, the bitmap at its origin (phase 0)
    db::TextureRecord tile;
    tile.kind = db::TextureKind::kPattern;
    tile.rgb = plan.found->tile_rgb;
    tile.mask = plan.found->tile_mask;
    tile.lattice = plan.found->lattice;
    tile.texel_m = bitmap.grid.texel_m;
    tile.source_patch = bitmap.id;
    auto described =
        match::patternTexture(0, tile.rgb, tile.mask, *tile.lattice, cascade_.config());
    tile.ccv = described->description.ccv.values;
    base.texture_id = addTexture(std::move(tile), std::move(described), commit, fresh);
    base.reused = base.texture_id > 0;
    record.method = base.reused ? "same pixels" : "pattern";
  }
  commit.instances.push_back(base);
  for (const OverlayMatch& overlay : plan.overlays) {
    db::TextureInstance layer = base;
    layer.layer = static_cast<int>(commit.instances.size());
    if (const auto& match = overlay.decision.match) {
      layer.texture_id = match->id;
      layer.transform = patchToBox(overlay.box).then(*match->transform);
      layer.psnr_db = match->psnr_db;
      layer.reused = true;
    } else {
      // Stored opaque (as the database will give it back); described as the crop was seen.
      db::TextureRecord crop = singleRecord(overlay.description, bitmap.grid.texel_m, bitmap.id);
      crop.rgb = overlay.opaque_rgb;
      crop.mask = cv::Mat(crop.rgb.size(), CV_8UC1, cv::Scalar(255));
      auto described = std::make_shared<match::StoredTexture>();
      described->description = overlay.description;
      described->description.rgb = crop.rgb;
      described->description.mask = crop.mask;
      layer.texture_id = addTexture(std::move(crop), std::move(described), commit, fresh);
      layer.transform = patchToBox(overlay.box);
      layer.psnr_db.reset();
      layer.reused = layer.texture_id > 0;
    }
    commit.instances.push_back(layer);
  }
}

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
  std::optional<match::CandidateVerdict> reuse;
  std::optional<LayerPlan> layers;
  if (cascade_.config().enabled) {
    match::MatchDecision decision;
    try {
      decision = cascade_.match(*described.description, catalog_);
    } catch (const std::exception& e) {  // one patch's failure costs its matching, not the run
      spdlog::warn("patch {} version {}: not matched: {}", bitmap.id, bitmap.version, e.what());
    }
    record.match_ms = decision.ms;
    record.ccv_considered = decision.considered;
    record.ccv_removed = decision.considered - std::min(decision.passed_ccv, decision.considered);
    ccv_considered_ += record.ccv_considered;
    ccv_removed_ += record.ccv_removed;
    reuse = decision.match;
    if (!reuse && planner_.config().enabled) layers = planLayers(described, decision, record);
  }
  match_timer_.add(record.match_ms + record.pattern_ms);

  db::Commit commit;
  std::vector<std::shared_ptr<match::StoredTexture>> fresh;  // parallel to commit.textures
  if (reuse) {
    db::TextureInstance instance;
    instance.run_id = run_id_;
    instance.patch_id = bitmap.id;
    instance.version = bitmap.version;
    instance.texture_id = reuse->id;
    instance.transform = *reuse->transform;
    instance.psnr_db = reuse->psnr_db;
    instance.reused = true;
    record.method = reuse->method;
    commit.instances.push_back(instance);
  } else if (layers) {
    planCommit(bitmap, *layers, commit, fresh, record);
  } else {
    db::TextureInstance instance;
    instance.run_id = run_id_;
    instance.patch_id = bitmap.id;
    instance.version = bitmap.version;
    db::TextureRecord texture =
        singleRecord(*described.description, bitmap.grid.texel_m, bitmap.id);
    texture.rgb = bitmap.image;
    auto stored = std::make_shared<match::StoredTexture>();
    stored->description = *described.description;
    instance.texture_id = addTexture(std::move(texture), std::move(stored), commit, fresh);
    instance.reused = instance.texture_id > 0;
    if (instance.reused) instance.psnr_db = 99.0;
    record.method = instance.reused ? "same pixels" : "stored";
    commit.instances.push_back(instance);
  }
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
  for (std::size_t i = 0; i < fresh.size(); ++i) {
    fresh[i]->id = ids.at(i);
    catalog_.add(fresh[i]);
    ++textures_stored_;
    patterns_stored_ += fresh[i]->pattern ? 1 : 0;
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
  commit.retired.push_back({run_id_, patch_id});
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
