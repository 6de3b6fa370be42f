#include "tessera/reuse/store_catalog.h"

#include <opencv2/core.hpp>

#include "tessera/match/ccv.h"

namespace tessera::reuse {

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
  // Stored under other settings: described again as a new bitmap is (at the described size).
  if (record.feature_kind != config.features.detector) {
    const match::TextureDescription again =
        match::describeTexture(record.rgb, record.mask, config);
    description.ccv.values = again.ccv.values;
    description.features = again.features;
  } else {
    description.features = {record.feature_kind, record.keypoints, record.descriptors};
    if (record.ccv.size() != match::ccvLength(config.ccv)) {
      description.ccv.values = match::describeColours(record.rgb, record.mask, config).ccv.values;
    }
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
      index_.add(entry.id, match::describeColours(record->rgb, record->mask, config).ccv.values);
    }
    ++size_;
  }
}

std::size_t StoreCatalog::size() const {
  const std::lock_guard lock(mutex_);
  return size_;
}

std::size_t StoreCatalog::cachedBytes() const {
  const std::lock_guard lock(mutex_);
  return cached_bytes_;
}

std::vector<match::CcvNeighbour> StoreCatalog::nearest(const std::vector<float>& ccv,
                                                       double max_distance, std::size_t k) const {
  const std::lock_guard lock(mutex_);
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

std::shared_ptr<const match::StoredTexture> StoreCatalog::cached(std::int64_t id) const {
  const auto it = cache_.find(id);
  if (it == cache_.end()) return nullptr;
  recency_.splice(recency_.begin(), recency_, it->second.recency);
  return it->second.texture;
}

std::shared_ptr<const match::StoredTexture> StoreCatalog::load(std::int64_t id) const {
  std::size_t removals = 0;
  {
    const std::lock_guard lock(mutex_);
    if (auto texture = cached(id)) return texture;
    removals = removals_;
  }
  // Read and described unlocked: other threads' look-ups need not wait for it.
  const std::optional<db::TextureRecord> record = store_.texture(id);
  if (!record) return nullptr;
  std::shared_ptr<const match::StoredTexture> texture = storedTextureOf(*record, config_);
  const std::lock_guard lock(mutex_);
  if (auto meanwhile = cached(id)) return meanwhile;  // added or loaded by another thread
  // A texture removed meanwhile is not cached: its id may come back for another one.
  if (removals == removals_) hold(texture);
  return texture;
}

std::vector<std::shared_ptr<const match::StoredTexture>> StoreCatalog::loadLayers(
    const std::vector<db::TextureInstance>& layers) const {
  std::vector<std::shared_ptr<const match::StoredTexture>> stored;
  for (const db::TextureInstance& layer : layers) {
    stored.push_back(load(layer.texture_id));
    if (!stored.back()) return {};
  }
  return stored;
}

ShownPatch shownPatch(std::size_t pixels, const std::vector<db::TextureInstance>& layers,
                      const std::vector<std::shared_ptr<const match::StoredTexture>>& stored) {
  ShownPatch shown{pixels, {}};
  for (std::size_t i = 0; i < stored.size(); ++i) {
    shown.layers.push_back({layers.at(i).texture_id, stored[i]->storedRgb().total(),
                            stored[i]->pattern, layers[i].reused, layers[i].psnr_db});
  }
  return shown;
}

void StoreCatalog::add(std::shared_ptr<const match::StoredTexture> texture) {
  const std::lock_guard lock(mutex_);
  // Undescribed (match.enabled false): kept for export, never a candidate.
  if (!texture->description.ccv.values.empty()) {
    index_.add(texture->id, texture->description.ccv.values);
    ++size_;
  }
  hold(std::move(texture));
}

void StoreCatalog::remove(std::int64_t id) {
  const std::lock_guard lock(mutex_);
  ++removals_;
  if (index_.remove(id)) --size_;
  if (const auto it = cache_.find(id); it != cache_.end()) {
    cached_bytes_ -= it->second.bytes;
    recency_.erase(it->second.recency);
    cache_.erase(it);
  }
}

db::TextureRecord textureRecordOf(const match::TextureDescription& description,
                                  db::TextureKind kind, double texel_m, int source_patch) {
  db::TextureRecord texture;
  texture.kind = kind;
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

}  // namespace tessera::reuse
