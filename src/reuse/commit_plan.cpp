#include "tessera/reuse/commit_plan.h"

#include <algorithm>
#include <chrono>

#include <spdlog/spdlog.h>

#include "tessera/reuse/layer_plan.h"
#include "tessera/reuse/store_catalog.h"

namespace tessera::reuse {

namespace {

using Clock = std::chrono::steady_clock;

double msSince(Clock::time_point start) {
  return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

// Layer 0 of `bitmap`'s patch, naming no texture yet.
db::TextureInstance instanceOf(const texture::PatchBitmap& bitmap, std::int64_t run_id) {
  db::TextureInstance instance;
  instance.run_id = run_id;
  instance.patch_id = bitmap.id;
  instance.version = bitmap.version;
  return instance;
}

// Builds the plan's commit from the decisions made.
class PlanWriter {
 public:
  PlanWriter(CommitPlan& plan, const StoredPixels& stored_pixels, std::int64_t run_id)
      : plan_(plan), stored_pixels_(stored_pixels), run_id_(run_id) {}

  // A new texture for the commit, or the id of one with the same pixels already stored
  // (negative: index into commit.textures, as db::Commit counts them).
  std::int64_t addTexture(db::TextureRecord texture,
                          std::shared_ptr<match::StoredTexture> described) {
    texture.content_key = db::contentKey(texture.rgb, texture.mask);
    texture.run_id = run_id_;
    // The very same pixels already stored (a rerun of a recording): that texture, as it is.
    if (const auto existing = stored_pixels_(texture.content_key)) return *existing;
    std::vector<db::TextureRecord>& textures = plan_.commit.textures;
    for (std::size_t i = 0; i < textures.size(); ++i) {
      if (textures[i].content_key == texture.content_key) {
        return -static_cast<std::int64_t>(i) - 1;
      }
    }
    textures.push_back(std::move(texture));
    plan_.fresh.push_back(std::move(described));
    return -static_cast<std::int64_t>(textures.size());
  }

  // A layer plan's textures and instances: layer 0 the base, then the overlays.
  void addLayers(const texture::PatchBitmap& bitmap, const LayerPlan& layers,
                 const match::MatchConfig& config) {
    db::TextureInstance base = instanceOf(bitmap, run_id_);
    base.psnr_db = layers.fidelity.psnr_db;
    if (layers.base_reuse) {
      base.texture_id = layers.base_reuse->id;
      base.transform = *layers.base_reuse->transform;
      base.reused = true;
      plan_.method = layers.base_reuse->method;
    } else {  // one cell of the pattern, the bitmap at its origin (phase 0)
      db::TextureRecord tile;
      tile.kind = db::TextureKind::kPattern;
      tile.rgb = layers.found->tile_rgb;
      tile.mask = layers.found->tile_mask;
      tile.lattice = layers.found->lattice;
      tile.texel_m = bitmap.grid.texel_m;
      tile.source_patch = bitmap.id;
      auto described = match::patternTexture(0, tile.rgb, tile.mask, *tile.lattice, config);
      tile.ccv = described->description.ccv.values;
      base.texture_id = addTexture(std::move(tile), std::move(described));
      base.reused = base.texture_id > 0;
      plan_.method = base.reused ? "same pixels" : "pattern";
    }
    std::vector<db::TextureInstance>& instances = plan_.commit.instances;
    instances.push_back(base);
    for (const OverlayMatch& overlay : layers.overlays) {
      db::TextureInstance layer = base;
      layer.layer = static_cast<int>(instances.size());
      if (const auto& match = overlay.decision.match) {
        layer.texture_id = match->id;
        layer.transform = patchToBox(overlay.box).then(*match->transform);
        layer.psnr_db = match->psnr_db;
        layer.reused = true;
      } else {
        // Stored opaque (as the database will give it back); described as the crop was seen.
        db::TextureRecord crop = textureRecordOf(overlay.description, db::TextureKind::kSingle,
                                                 bitmap.grid.texel_m, bitmap.id);
        crop.rgb = overlay.opaque_rgb;
        crop.mask = cv::Mat(crop.rgb.size(), CV_8UC1, cv::Scalar(255));
        auto described = std::make_shared<match::StoredTexture>();
        described->description = overlay.description;
        described->description.rgb = crop.rgb;
        described->description.mask = crop.mask;
        layer.texture_id = addTexture(std::move(crop), std::move(described));
        layer.transform = patchToBox(overlay.box);
        layer.psnr_db.reset();
        layer.reused = layer.texture_id > 0;
      }
      instances.push_back(layer);
    }
  }

  // A stored texture that shows the bitmap whole.
  void addReuse(const texture::PatchBitmap& bitmap, const match::CandidateVerdict& reuse) {
    db::TextureInstance instance = instanceOf(bitmap, run_id_);
    instance.texture_id = reuse.id;
    instance.transform = *reuse.transform;
    instance.psnr_db = reuse.psnr_db;
    instance.reused = true;
    plan_.method = reuse.method;
    plan_.commit.instances.push_back(instance);
  }

  // The bitmap as its own texture (or the stored texture with the same pixels).
  void addWhole(const texture::PatchBitmap& bitmap, const match::TextureDescription& description) {
    db::TextureInstance instance = instanceOf(bitmap, run_id_);
    db::TextureRecord texture =
        textureRecordOf(description, db::TextureKind::kSingle, bitmap.grid.texel_m, bitmap.id);
    texture.rgb = bitmap.image;
    auto stored = std::make_shared<match::StoredTexture>();
    stored->description = description;
    instance.texture_id = addTexture(std::move(texture), std::move(stored));
    instance.reused = instance.texture_id > 0;
    if (instance.reused) instance.psnr_db = match::kIdenticalPsnrDb;
    plan_.method = instance.reused ? "same pixels" : "stored";
    plan_.commit.instances.push_back(instance);
  }

 private:
  CommitPlan& plan_;
  const StoredPixels& stored_pixels_;
  std::int64_t run_id_;
};

// A bitmap that matched nothing whole: its layers, when together they pass the acceptance rule.
std::optional<LayerPlan> planLayers(const texture::PatchBitmap& bitmap,
                                    const match::TextureDescription& description,
                                    const std::optional<pattern::Pattern>& found,
                                    const match::MatchDecision& decision,
                                    const LayerPlanner& planner) {
  try {
    std::optional<LayerPlan> layers;
    if (found) layers = planner.planPattern(description, *found);
    // A bitmap that nothing shows whole may be a stored texture with some regions changed (the
    // same plaster, another poster on it).
    if (!layers) layers = planner.planPartialReuse(description, decision.verdicts);
    return layers;
  } catch (const std::exception& e) {  // then stored whole
    spdlog::warn("patch {} version {}: no layers: {}", bitmap.id, bitmap.version, e.what());
    return std::nullopt;
  }
}

}  // namespace

CommitPlan planCommit(const texture::PatchBitmap& bitmap,
                      const match::TextureDescription& description,
                      const std::optional<pattern::Pattern>& found,
                      const match::TextureCatalog& catalog, const StoredPixels& stored_pixels,
                      const CommitRules& rules, const match::PrecheckedVerdicts* prechecked,
                      const PreparedLayers* prepared) {
  CommitPlan plan;
  PlanWriter writer(plan, stored_pixels, rules.run_id);
  if (!rules.match.enabled) {
    writer.addWhole(bitmap, description);
    return plan;
  }
  const match::MatchCascade cascade(rules.match);
  match::MatchDecision decision;
  try {
    decision = cascade.match(description, catalog, prechecked);
  } catch (const std::exception& e) {  // one patch's failure costs its matching, not the run
    spdlog::warn("patch {} version {}: not matched: {}", bitmap.id, bitmap.version, e.what());
  }
  plan.match_ms = decision.ms;
  plan.ccv_considered = decision.considered;
  plan.ccv_removed = decision.considered - std::min(decision.passed_ccv, decision.considered);
  if (decision.match) {
    writer.addReuse(bitmap, *decision.match);
    return plan;
  }
  if (rules.patterns.enabled) {
    const Clock::time_point start = Clock::now();
    const LayerPlanner planner(cascade, catalog, rules.patterns, prepared);
    const std::optional<LayerPlan> layers =
        planLayers(bitmap, description, found, decision, planner);
    plan.layers_ms = msSince(start);
    if (layers) {
      writer.addLayers(bitmap, *layers, rules.match);
      return plan;
    }
  }
  writer.addWhole(bitmap, description);
  return plan;
}

}  // namespace tessera::reuse
