#include <filesystem>
#include <set>

#include <fmt/format.h>

#include "internal/run_parts.h"
#include "tessera/map_export/map_files.h"
#include "tessera/map_export/patch_files.h"
#include "tessera/texture/bitmap_export.h"

namespace tessera::pipeline::internal {

namespace {

// Gives each exported patch the database texture its newest instance names, writes each such
// texture once (OUT/textures/texture_<id>.png), and fills the summary's economy figures.
void bindMapTextures(const db::TextureStore& store, const CommitStage& commits,
                     const reuse::StoreCatalog& catalog, const std::filesystem::path& out_dir,
                     planes::TextureBindings& bindings, RunSummary& summary) {
  std::set<std::int64_t> used;
  // One layer as the map shows it; each database texture is written (and counted) once.
  const auto show = [&](const db::TextureInstance& instance, const match::StoredTexture& stored) {
    const cv::Mat& rgb = stored.storedRgb();
    planes::MapTexture shown;
    shown.texture_id = store.resolvedId(instance.texture_id);  // the server's id, once sent
    shown.image = fmt::format("textures/texture_{}.png", shown.texture_id);
    shown.width = rgb.cols;
    shown.height = rgb.rows;
    shown.transform = instance.transform;
    shown.tiled = stored.pattern;
    if (stored.pattern) shown.lattice = stored.lattice;
    shown.reused = instance.reused;
    shown.psnr_db = instance.psnr_db;
    if (instance.reused)
      (stored.pattern ? summary.patterns_matched : summary.textures_matched) += 1;
    if (used.insert(shown.texture_id).second) {
      texture::writeRgbaPng(out_dir / shown.image, rgb, stored.storedMask());
      summary.pixels_after += rgb.total();
    }
    return shown;
  };
  for (auto& [patch_id, binding] : bindings) {
    summary.pixels_before += static_cast<std::size_t>(binding.width) * binding.height;
    const auto it = commits.instances().find(patch_id);
    const bool current = it != commits.instances().end() && !it->second.empty() &&
                         it->second.front().version == binding.version;
    std::vector<std::shared_ptr<const match::StoredTexture>> layers;
    if (current) {
      for (const db::TextureInstance& instance : it->second) {
        layers.push_back(catalog.load(instance.texture_id));
        if (!layers.back()) layers.clear();
        if (layers.empty()) break;
      }
    }
    if (layers.empty()) {  // not committed: the map shows the patch's own bitmap
      summary.pixels_after += static_cast<std::size_t>(binding.width) * binding.height;
      continue;
    }
    const db::TextureInstance& instance = it->second.front();
    binding.map_texture = show(instance, *layers.front());
    for (std::size_t i = 1; i < layers.size(); ++i) {
      binding.overlays.push_back(show(it->second[i], *layers[i]));
    }
    summary.overlays += layers.size() - 1;
    summary.textured_patches += 1;
    summary.reuses += instance.reused ? 1 : 0;
    // A reuse or a pattern shows the patch through another image: its fidelity counts.
    if (instance.psnr_db) summary.shown_psnrs_db.push_back(*instance.psnr_db);
  }
  summary.textures_stored = commits.texturesStored();
  summary.patterns_stored = commits.patternsStored();
  summary.commit_failures = commits.commitFailures();
  summary.ccv_considered = commits.ccvConsidered();
  summary.ccv_removed = commits.ccvRemoved();
}

}  // namespace

void exportRun(RunParts& parts, const RunOptions& options, RunSummary& summary) {
  // The mesh is written even when the source ended abnormally, so work is kept.
  const auto mesh = parts.integration.map().extractMesh();
  summary.mesh_vertices = mesh.vertices.size();
  fusion::writePly(mesh, options.out_dir / "mesh.ply");
  const planes::PatchMap& patches = parts.planes.map();
  summary.patches_finalized = patches.finalizedCount();
  summary.patch_finalizations = parts.planes.finalizations();
  summary.patches_retired = parts.planes.retirements();
  for (const planes::Patch& patch : patches.patches()) {
    summary.colour_samples += patch.samples.size();
    summary.colour_sample_bytes += patch.samples.bytes();
  }
  summary.samples_released = patches.samplesReleased();
  std::error_code ignored;
  std::filesystem::remove_all(parts.sample_dir, ignored);
  parts.bitmaps.flush();
  planes::TextureBindings textures =
      texture::currentBindings(parts.bitmaps.written(), patches, options.out_dir);
  summary.db = parts.store->location();
  summary.server_link = parts.store->serverLink();
  summary.db_run_id = parts.run_id;
  for (const auto& [patch, layers] : parts.commit.instances())
    summary.db_instances += layers.size();
  bindMapTextures(*parts.store, parts.commit, parts.catalog, options.out_dir, textures, summary);
  for (const auto& [id, binding] : textures) {
    summary.bitmaps += 1;
    summary.bitmap_texels_observed += binding.observed;
    summary.bitmap_texels_inpainted += binding.inpainted;
    summary.bitmap_bytes += 3 * static_cast<std::size_t>(binding.width) * binding.height;
  }
  if (parts.bitmaps.areaBuiltM2() > 0.0) {
    summary.bitmap_ms_per_m2 = parts.bitmaps.timer().totalMs() / parts.bitmaps.areaBuiltM2();
  }
  map_export::writePatchesObj(patches, options.out_dir / "patches.obj", textures);
  // The map users open: patches triangulated with their holes, one material per texture.
  const map_export::MapModel map_model =
      map_export::buildMapModel(patches, textures, options.residual ? &mesh : nullptr);
  map_export::writeMapObj(map_model, options.out_dir / "map.obj");
  map_export::writeMapGlb(map_model, options.out_dir, options.out_dir / "map.glb");
  summary.map_triangles = map_model.triangleCount();
  map_export::writePatchesJson(patches, options.out_dir / "patches.json", textures);
}

}  // namespace tessera::pipeline::internal
