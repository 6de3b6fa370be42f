#pragma once
// The reuse decision for one finalized patch: what its bitmap becomes in the texture database.
// In order of preference:
//   1. a stored texture that shows it whole (the cascade's match): one reused instance;
//   2. layers (layer_plan.h): a periodic pattern, new or stored, or a stored texture with
//      some regions changed, each region an overlay that reuses a texture or stores its crop;
//   3. its own bitmap as a new texture.
// The same pixels are never stored twice: a texture whose content key the database or the
// plan already has is named, not added. planCommit reads the catalog and writes nothing, so
// that the commit stage stores the plan in one transaction, and tests can plan against a
// catalog in memory.
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "tessera/db/texture_store.h"
#include "tessera/match/match_cascade.h"
#include "tessera/pattern/pattern_config.h"
#include "tessera/reuse/layer_plan.h"
#include "tessera/texture/bitmap_builder.h"

namespace tessera::reuse {

// What the plan follows.
struct CommitRules {
  match::MatchConfig match;              // match.enabled false: every bitmap is stored as it is
  pattern::PatternStageConfig patterns;  // patterns.enabled false: no layers
  std::int64_t run_id = 0;               // written into the plan's textures and instances
};

// The id of a stored texture with exactly these pixels (db::contentKey), if any.
using StoredPixels = std::function<std::optional<std::int64_t>(const std::string& content_key)>;

struct CommitPlan {
  // New textures, and the patch's instances (layer 0, then its overlays); an instance names a
  // new texture by a negative id, as db::Commit counts them.
  db::Commit commit;
  // Descriptions of commit.textures (parallel), for the catalog once they have ids.
  std::vector<std::shared_ptr<match::StoredTexture>> fresh;
  // How layer 0 was decided: "ncc", "features", "lattice" (+"overlays"), "pattern",
  // "same pixels" or "stored".
  std::string method;
  std::size_t ccv_considered = 0, ccv_removed = 0;  // the cascade's prefilter
  double match_ms = 0.0;                            // the cascade
  double layers_ms = 0.0;                           // planning layers

  const db::TextureInstance& base() const { return commit.instances.front(); }
};

// Plans the commit of `bitmap`, described by `description` (with `found`, the periodic
// pattern in it when one was found), against `catalog`; `prechecked` (MatchCascade::precheck)
// and `prepared` (LayerPlanner::prepare) save working out again what they worked out, with
// the same plan. Never throws for a failed match or layer plan (logged; the bitmap is then
// stored whole).
CommitPlan planCommit(const texture::PatchBitmap& bitmap,
                      const match::TextureDescription& description,
                      const std::optional<pattern::Pattern>& found,
                      const match::TextureCatalog& catalog, const StoredPixels& stored_pixels,
                      const CommitRules& rules,
                      const match::PrecheckedVerdicts* prechecked = nullptr,
                      const PreparedLayers* prepared = nullptr);

}  // namespace tessera::reuse
