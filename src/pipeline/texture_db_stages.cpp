#include "tessera/pipeline/texture_db_stages.h"

#include <algorithm>

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
    newest_id_ = std::max(newest_id_, entry.id);
  }
}

std::vector<match::CcvNeighbour> StoreCatalog::nearest(const std::vector<float>& ccv,
                                                       double max_distance, std::size_t k) const {
  return index_.query(ccv, max_distance, k);
}

std::shared_ptr<const match::StoredTexture> StoreCatalog::load(std::int64_t id) const {
  {
    std::lock_guard lock(cache_mutex_);
    if (const auto it = cache_.find(id); it != cache_.end()) return it->second;
  }
  const std::optional<db::TextureRecord> record = store_.texture(id);
  if (!record) return nullptr;
  std::shared_ptr<const match::StoredTexture> stored = storedTextureOf(*record, config_);
  std::lock_guard lock(cache_mutex_);
  return cache_.emplace(id, std::move(stored)).first->second;
}

void StoreCatalog::add(std::shared_ptr<const match::StoredTexture> texture) {
  std::unique_lock lock(mutex_);
  // Undescribed (match.enabled false): kept for export, never a candidate.
  if (texture->description.ccv.values.empty()) {
    std::lock_guard cache_lock(cache_mutex_);
    cache_[texture->id] = std::move(texture);
    return;
  }
  index_.add(texture->id, texture->description.ccv.values);
  ++size_;
  newest_id_ = std::max(newest_id_, texture->id);
  std::lock_guard cache_lock(cache_mutex_);
  cache_[texture->id] = std::move(texture);
}

MatchedPatch MatchStage::process(const PatchJob& job) const {
  MatchedPatch matched;
  matched.sequence = job.sequence;
  matched.batch = job.batch;
  matched.batch_size = job.batch_size;
  matched.frame_index = job.frame_index;
  matched.finalized_at = job.finalized_at;
  matched.bitmap = textures_.build(job.patch);
  if (!matched.bitmap) return matched;
  if (!cascade_.config().enabled) {  // stored as it is: no description, no candidates
    matched.description =
        match::TextureDescription{matched.bitmap->image, validTexels(*matched.bitmap), {}, {}};
    return matched;
  }
  try {
    const SteadyTime start = std::chrono::steady_clock::now();
    matched.description = match::describeTexture(matched.bitmap->image,
                                                 validTexels(*matched.bitmap), cascade_.config());
    matched.describe_ms = msSince(start);
    const auto lock = catalog_.readLock();
    matched.snapshot_id = catalog_.newestId();
    matched.decision = cascade_.match(*matched.description, catalog_);
  } catch (const std::exception& e) {  // one patch's failure costs its matching, not the run
    spdlog::warn("patch {} version {}: not matched: {}", job.patch.id, job.patch.version, e.what());
    matched.description.reset();
    return matched;
  }
  if (!matched.decision.match && planner_.config().enabled) findPattern(planner_, matched);
  return matched;
}

CommitStage::CommitStage(db::TextureStore& store, StoreCatalog& catalog,
                         const match::MatchCascade& cascade,
                         const pattern::PatternStageConfig& patterns, std::int64_t run_id)
    : store_(store),
      catalog_(catalog),
      cascade_(cascade),
      planner_(cascade, catalog, patterns),
      run_id_(run_id) {}

std::vector<match::CandidateVerdict> CommitStage::allVerdicts(const MatchedPatch& matched) const {
  const match::TextureDescription& query = *matched.description;
  std::vector<match::CandidateVerdict> verdicts = matched.decision.verdicts;
  for (const auto& texture : committed_) {
    if (texture->id <= matched.snapshot_id) continue;
    const double d = match::ccvDistance(query.ccv.values, texture->description.ccv.values);
    if (d <= cascade_.config().ccv_max_distance) {
      verdicts.push_back(cascade_.tryCandidate(query, *texture, d));
    }
  }
  std::sort(verdicts.begin(), verdicts.end(), [](const auto& a, const auto& b) {
    return a.ccv_distance != b.ccv_distance ? a.ccv_distance < b.ccv_distance : a.id < b.id;
  });
  if (verdicts.size() > cascade_.config().max_candidates) {
    verdicts.resize(cascade_.config().max_candidates);
  }
  return verdicts;
}

std::optional<match::CandidateVerdict> CommitStage::recheck(const MatchedPatch& matched,
                                                            std::size_t& newer_passing) const {
  // The max_candidates textures nearest in CCV among everything stored so far, in the order
  // the matcher takes them, the first accepted winning: the matcher's verdicts stand for the
  // textures it saw (every one before the one it accepted was refused), the cascade runs on
  // those committed since its snapshot. A newer texture that pushes the matcher's choice out of
  // the nearest max_candidates takes it out of the running, as it would have in order.
  struct Entry {
    double distance;
    std::int64_t id;
    const match::CandidateVerdict* seen;  // the matcher's verdict, or null for a newer texture
  };
  const match::TextureDescription& query = *matched.description;
  const double bound = cascade_.config().ccv_max_distance;
  std::vector<Entry> entries;
  for (const match::CandidateVerdict& verdict : matched.decision.verdicts) {
    entries.push_back({verdict.ccv_distance, verdict.id, &verdict});
  }
  newer_passing = 0;
  for (const auto& texture : committed_) {
    if (texture->id <= matched.snapshot_id) continue;
    const double d = match::ccvDistance(query.ccv.values, texture->description.ccv.values);
    if (d > bound) continue;
    ++newer_passing;
    entries.push_back({d, texture->id, nullptr});
  }
  std::sort(entries.begin(), entries.end(), [](const Entry& a, const Entry& b) {
    return a.distance != b.distance ? a.distance < b.distance : a.id < b.id;
  });
  if (entries.size() > cascade_.config().max_candidates) {
    entries.resize(cascade_.config().max_candidates);
  }
  for (const Entry& entry : entries) {
    if (entry.seen != nullptr) {
      if (entry.seen->accepted) return *entry.seen;
      continue;
    }
    const auto stored = std::find_if(committed_.begin(), committed_.end(),
                                     [&](const auto& t) { return t->id == entry.id; });
    match::CandidateVerdict verdict = cascade_.tryCandidate(query, **stored, entry.distance);
    if (verdict.accepted) return verdict;
  }
  return std::nullopt;
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

bool CommitStage::planCommit(const MatchedPatch& matched, db::Commit& commit,
                             std::vector<std::shared_ptr<match::StoredTexture>>& fresh,
                             CommitRecord& record) const {
  const texture::PatchBitmap& bitmap = *matched.bitmap;
  LayerPlan plan = *matched.layers;
  if (plan.found && catalog_.newestId() > matched.snapshot_id) {
    // Textures were committed after the matcher's snapshot: the pattern plan is made again over
    // all of them, so that the outcome is the one a matcher that saw every earlier commit
    // would have reached, whatever the threads' timing (patching the old plan with the newer
    // textures left one or two threads storing different textures under load).
    const auto start = std::chrono::steady_clock::now();
    std::optional<LayerPlan> again;
    try {
      again = planner_.planPattern(*matched.description, *plan.found);
    } catch (const std::exception& e) {  // then stored whole
      spdlog::warn("patch {} version {}: no layers: {}", bitmap.id, bitmap.version, e.what());
    }
    record.pattern_ms += msSince(start);
    if (!again) return false;
    plan = std::move(*again);
  }

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
  return true;
}

CommitRecord CommitStage::process(MatchedPatch matched) {
  ScopedStageTime time(timer_);
  CommitRecord record;
  if (!matched.bitmap) return record;
  const texture::PatchBitmap& bitmap = *matched.bitmap;
  record.patch_id = bitmap.id;
  record.version = bitmap.version;
  record.bitmap_ms = bitmap.build_ms;
  record.describe_ms = matched.describe_ms;
  record.match_ms = matched.decision.ms;
  record.pattern_ms = matched.pattern_ms;
  match_timer_.add(matched.decision.ms + matched.pattern_ms);
  if (!matched.description) return record;

  db::Commit commit;
  std::size_t newer_passing = 0;
  const std::optional<match::CandidateVerdict> reuse =
      cascade_.config().enabled ? recheck(matched, newer_passing) : std::nullopt;
  if (cascade_.config().enabled) {
    // As if every earlier patch had been committed before this one was matched, whatever the
    // matcher's snapshot held: the prefilter considered every texture stored so far and let
    // through at most max_candidates of those within its bound.
    record.ccv_considered = catalog_.size();
    const std::size_t passing =
        std::min(cascade_.config().max_candidates, matched.decision.passed_ccv + newer_passing);
    record.ccv_removed = record.ccv_considered - std::min(passing, record.ccv_considered);
    ccv_considered_ += record.ccv_considered;
    ccv_removed_ += record.ccv_removed;
  }
  if (!reuse && matched.decision.match && !matched.layers && cascade_.config().enabled &&
      planner_.config().enabled) {
    // The matcher's choice fell out of the nearest textures once the newer ones counted, so it
    // never looked for a pattern: looked for here, as a matcher that saw them would have.
    findPattern(planner_, matched);
    matched.snapshot_id = catalog_.newestId();
    record.pattern_ms = matched.pattern_ms;
  }
  // A bitmap that nothing shows whole may be a stored texture with some regions changed (the
  // same plaster, another poster on it): planned here, where every earlier texture is known,
  // so that the outcome does not depend on what the matcher's snapshot held.
  if (!reuse && !matched.layers && cascade_.config().enabled && planner_.config().enabled) {
    const auto start = std::chrono::steady_clock::now();
    try {
      matched.layers = planner_.planPartialReuse(*matched.description, allVerdicts(matched));
    } catch (const std::exception& e) {  // then stored whole
      spdlog::warn("patch {} version {}: no layers: {}", bitmap.id, bitmap.version, e.what());
    }
    matched.snapshot_id = catalog_.newestId();  // the plan saw every committed texture
    record.pattern_ms += msSince(start);
  }
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
  } else if (matched.layers && planCommit(matched, commit, fresh, record)) {
    // stored in layers
  } else {
    db::TextureInstance instance;
    instance.run_id = run_id_;
    instance.patch_id = bitmap.id;
    instance.version = bitmap.version;
    db::TextureRecord texture = singleRecord(*matched.description, bitmap.grid.texel_m, bitmap.id);
    texture.rgb = bitmap.image;
    auto described = std::make_shared<match::StoredTexture>();
    described->description = *matched.description;
    instance.texture_id = addTexture(std::move(texture), std::move(described), commit, fresh);
    instance.reused = instance.texture_id > 0;
    if (instance.reused) instance.psnr_db = 99.0;
    record.method = instance.reused ? "same pixels" : "stored";
    commit.instances.push_back(instance);
  }
  std::vector<std::int64_t> ids;
  try {
    ids = store_.commit(commit);
  } catch (const core::Error& e) {
    // The map keeps the patch's own bitmap; the database keeps every earlier commit.
    spdlog::error("patch {} version {}: not committed: {}", bitmap.id, bitmap.version, e.what());
    ++commit_failures_;
    return record;
  }
  for (std::size_t i = 0; i < fresh.size(); ++i) {
    fresh[i]->id = ids.at(i);
    committed_.push_back(fresh[i]);
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
  record.instance = commit.instances.front();
  record.overlays.assign(commit.instances.begin() + 1, commit.instances.end());
  record.commit_latency_ms = msSince(matched.finalized_at);
  commit_latencies_ms_.push_back(record.commit_latency_ms);
  return record;
}

}  // namespace tessera::pipeline
