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
  if (!matched.decision.match && patterns_.enabled) findPattern(matched);
  return matched;
}

void MatchStage::findPattern(MatchedPatch& matched) const {
  const match::TextureDescription& bitmap = *matched.description;
  try {
    pattern::PatternAnalysis analysis =
        pattern::analysePattern(bitmap.rgb, bitmap.mask, patterns_.extractor);
    matched.pattern_ms = analysis.ms;
    if (!analysis.pattern) return;
    // Stored only if the tiling shows the patch as faithfully as a reuse must, over all its
    // texels: a wall with a poster the pattern does not explain keeps its own bitmap.
    const pattern::Pattern& found = *analysis.pattern;
    const match::Fidelity fidelity =
        match::measureFidelity(bitmap.rgb, bitmap.mask,
                               match::renderPattern(found.tile_rgb, found.tile_mask, found.lattice,
                                                    {}, bitmap.rgb.cols, bitmap.rgb.rows));
    const match::MatchConfig& limits = cascade_.config();
    if (fidelity.psnr_db >= limits.min_psnr_db && fidelity.coverage >= limits.min_coverage) {
      matched.pattern = std::move(analysis.pattern);
      matched.pattern_fidelity = fidelity;
    } else {
      spdlog::debug(
          "patch {} version {}: a {}x{} pattern tile shows it at {:.1f} dB over {:.0f} % "
          "of it, short of a reuse's {:.1f} dB over {:.0f} %: stored whole",
          matched.bitmap->id, matched.bitmap->version, found.tile_rgb.cols, found.tile_rgb.rows,
          fidelity.psnr_db, 100.0 * fidelity.coverage, limits.min_psnr_db,
          100.0 * limits.min_coverage);
    }
  } catch (const std::exception& e) {  // the bitmap is then stored as it is
    spdlog::warn("patch {} version {}: no pattern analysis: {}", matched.bitmap->id,
                 matched.bitmap->version, e.what());
  }
}

CommitStage::CommitStage(db::TextureStore& store, StoreCatalog& catalog,
                         const match::MatchCascade& cascade, std::int64_t run_id)
    : store_(store), catalog_(catalog), cascade_(cascade), run_id_(run_id) {}

std::optional<match::CandidateVerdict> CommitStage::recheck(const MatchedPatch& matched,
                                                            std::size_t& newer_passing) const {
  const match::TextureDescription& query = *matched.description;
  const double bound = cascade_.config().ccv_max_distance;
  const double limit = matched.decision.match ? matched.decision.match->ccv_distance : bound;
  std::vector<match::CcvNeighbour> newer;
  newer_passing = 0;
  for (const auto& texture : committed_) {
    if (texture->id <= matched.snapshot_id) continue;
    const double d = match::ccvDistance(query.ccv.values, texture->description.ccv.values);
    newer_passing += d <= bound ? 1 : 0;
    const bool nearer = matched.decision.match ? d < limit : d <= limit;
    if (nearer) newer.push_back({texture->id, d});
  }
  std::sort(newer.begin(), newer.end(), [](const auto& a, const auto& b) {
    return a.distance != b.distance ? a.distance < b.distance : a.id < b.id;
  });
  if (newer.size() > cascade_.config().max_candidates)
    newer.resize(cascade_.config().max_candidates);
  for (const match::CcvNeighbour& candidate : newer) {
    const auto stored = std::find_if(committed_.begin(), committed_.end(),
                                     [&](const auto& t) { return t->id == candidate.id; });
    match::CandidateVerdict verdict = cascade_.tryCandidate(query, **stored, candidate.distance);
    if (verdict.accepted) return verdict;
  }
  return matched.decision.match;
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

  db::TextureInstance instance;
  instance.run_id = run_id_;
  instance.patch_id = bitmap.id;
  instance.version = bitmap.version;
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
  std::shared_ptr<match::StoredTexture> fresh;
  if (reuse) {
    instance.texture_id = reuse->id;
    instance.transform = *reuse->transform;
    instance.psnr_db = reuse->psnr_db;
    instance.reused = true;
    record.method = reuse->method;
  } else {
    db::TextureRecord texture;
    texture.kind = db::TextureKind::kSingle;
    texture.rgb = bitmap.image;
    texture.mask = matched.description->mask;
    texture.texel_m = bitmap.grid.texel_m;
    texture.ccv = matched.description->ccv.values;
    texture.feature_kind = matched.description->features.kind;
    texture.keypoints = matched.description->features.keypoints;
    texture.descriptors = matched.description->features.descriptors;
    texture.content_key = db::contentKey(texture.rgb, texture.mask);
    texture.run_id = run_id_;
    texture.source_patch = bitmap.id;
    if (matched.pattern) {  // one cell of the pattern, the bitmap at its origin (phase 0)
      const pattern::Pattern& found = *matched.pattern;
      texture.kind = db::TextureKind::kPattern;
      texture.rgb = found.tile_rgb;
      texture.mask = found.tile_mask;
      texture.lattice = found.lattice;
      texture.feature_kind.clear();
      texture.keypoints.clear();
      texture.descriptors = cv::Mat();
      texture.content_key = db::contentKey(texture.rgb, texture.mask);
      instance.psnr_db = matched.pattern_fidelity->psnr_db;
    }
    // The very same pixels already stored (a rerun of a recording): that texture, as it is.
    if (const auto existing = store_.findByContentKey(texture.content_key)) {
      instance.texture_id = *existing;
      instance.psnr_db = matched.pattern ? matched.pattern_fidelity->psnr_db : 99.0;
      instance.reused = true;
      record.method = "same pixels";
    } else {
      if (matched.pattern) {
        fresh = match::patternTexture(0, texture.rgb, texture.mask, *texture.lattice,
                                      cascade_.config());
        texture.ccv = fresh->description.ccv.values;
        record.method = "pattern";
      } else {
        fresh = std::make_shared<match::StoredTexture>();
        fresh->description = *matched.description;
        record.method = "stored";
      }
      commit.textures.push_back(std::move(texture));
      instance.texture_id = -1;
    }
  }
  commit.instances.push_back(instance);
  std::vector<std::int64_t> ids;
  try {
    ids = store_.commit(commit);
  } catch (const core::Error& e) {
    // The map keeps the patch's own bitmap; the database keeps every earlier commit.
    spdlog::error("patch {} version {}: not committed: {}", bitmap.id, bitmap.version, e.what());
    ++commit_failures_;
    return record;
  }
  if (fresh) {
    instance.texture_id = ids.at(0);
    fresh->id = ids.at(0);
    committed_.push_back(fresh);
    catalog_.add(fresh);
    ++textures_stored_;
    patterns_stored_ += fresh->pattern ? 1 : 0;
  }
  if (!texture_pixels_.count(instance.texture_id)) {
    const auto stored = catalog_.load(instance.texture_id);
    texture_pixels_[instance.texture_id] =
        stored ? stored->storedRgb().total() : bitmap.grid.texels();
  }
  instances_[bitmap.id] = instance;
  record.instance = instance;
  record.commit_latency_ms = msSince(matched.finalized_at);
  commit_latencies_ms_.push_back(record.commit_latency_ms);
  return record;
}

}  // namespace tessera::pipeline
