#pragma once
// The texture database as the matching cascade sees it, and the conversions between a
// database record and a described texture.
#include <cstddef>
#include <cstdint>
#include <list>
#include <map>
#include <memory>
#include <mutex>
#include <vector>

#include "tessera/db/texture_store.h"
#include "tessera/match/match_cascade.h"
#include "tessera/reuse/map_economy.h"

namespace tessera::reuse {

// The database's textures: their CCVs in an index, the textures themselves loaded on demand
// and kept, least recently used out first beyond MatchConfig::catalog_cache_mb (at least one).
// Thread-safe: the commit stage writes it while the describing threads look up candidates.
class StoreCatalog : public match::TextureCatalog {
 public:
  StoreCatalog(const db::TextureStore& store, const match::MatchConfig& config);

  std::size_t size() const override;
  std::vector<match::CcvNeighbour> nearest(const std::vector<float>& ccv, double max_distance,
                                           std::size_t k) const override;
  std::shared_ptr<const match::StoredTexture> load(std::int64_t id) const override;

  // The stored textures of a patch's layers, in order; none when one cannot be loaded (the map
  // then shows the patch's own bitmap).
  std::vector<std::shared_ptr<const match::StoredTexture>> loadLayers(
      const std::vector<db::TextureInstance>& layers) const;

  // After a commit.
  void add(std::shared_ptr<const match::StoredTexture> texture);
  // After the store removed texture `id` (TextureStore::removeUnused): no longer a candidate.
  void remove(std::int64_t id);
  // Bytes of the textures held in memory now.
  std::size_t cachedBytes() const;

 private:
  // Holds `texture` as the most recently used, dropping the least recently used beyond the
  // budget (never the one just held). The caller holds mutex_.
  void hold(std::shared_ptr<const match::StoredTexture> texture) const;
  // The cached texture `id`, now the most recently used, or null. The caller holds mutex_.
  std::shared_ptr<const match::StoredTexture> cached(std::int64_t id) const;

  struct Cached {
    std::shared_ptr<const match::StoredTexture> texture;
    std::size_t bytes = 0;
    std::list<std::int64_t>::iterator recency;
  };
  const db::TextureStore& store_;
  match::MatchConfig config_;
  mutable std::mutex mutex_;  // everything below
  match::CcvIndex index_;
  std::size_t size_ = 0;
  mutable std::map<std::int64_t, Cached> cache_;
  mutable std::list<std::int64_t> recency_;  // most recently used first
  mutable std::size_t cached_bytes_ = 0;
  std::size_t removals_ = 0;  // remove() calls so far
};

// A patch of `pixels` texels as the map shows it: through `stored` (loadLayers of `layers`),
// or its own bitmap when `stored` is empty.
ShownPatch shownPatch(std::size_t pixels, const std::vector<db::TextureInstance>& layers,
                      const std::vector<std::shared_ptr<const match::StoredTexture>>& stored);

// A database record as the cascade sees it; its CCV and features are computed again when the
// record's were made under other settings.
std::shared_ptr<const match::StoredTexture> storedTextureOf(const db::TextureRecord& record,
                                                            const match::MatchConfig& config);

// A described texture as a record to store: its pixels, CCV and features (no lattice, no
// content key; texel_m 0 and source_patch -1 when unknown).
db::TextureRecord textureRecordOf(const match::TextureDescription& description,
                                  db::TextureKind kind, double texel_m = 0.0,
                                  int source_patch = -1);

}  // namespace tessera::reuse
