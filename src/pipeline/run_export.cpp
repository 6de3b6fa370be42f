#include <chrono>
#include <filesystem>
#include <map>
#include <set>

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include "internal/run_parts.h"
#include "tessera/core/error.h"
#include "tessera/fusion/mesh_colours.h"
#include "tessera/fusion/surface_merge.h"
#include "tessera/map_export/map_files.h"
#include "tessera/map_export/patch_files.h"
#include "tessera/texture/bitmap_export.h"

namespace tessera::pipeline::internal {

namespace {

// Gives each exported patch the database textures its newest instances name, and writes each
// such texture once (OUT/textures/texture_<id>.png). Returns the map's texture economy: each
// patch as the map shows it.
reuse::Economy bindMapTextures(const db::TextureStore& store, const CommitStage& commits,
                               const reuse::StoreCatalog& catalog,
                               const std::filesystem::path& out_dir,
                               planes::TextureBindings& bindings) {
  std::set<std::int64_t> written;
  // One layer as the map shows it; each database texture is written once.
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
    if (written.insert(shown.texture_id).second) {
      texture::writeRgbaPng(out_dir / shown.image, rgb, stored.storedMask());
    }
    return shown;
  };
  std::map<int, reuse::ShownPatch> map;
  for (auto& [patch_id, binding] : bindings) {
    const std::size_t pixels = static_cast<std::size_t>(binding.width) * binding.height;
    const auto it = commits.instances().find(patch_id);
    const bool current = it != commits.instances().end() && !it->second.empty() &&
                         it->second.front().version == binding.version;
    const std::vector<db::TextureInstance> none;
    const std::vector<db::TextureInstance>& layers = current ? it->second : none;
    const auto stored = catalog.loadLayers(layers);
    map[patch_id] = reuse::shownPatch(pixels, layers, stored);
    if (stored.empty()) continue;  // not committed: the map shows the patch's own bitmap
    binding.map_texture = show(layers.front(), *stored.front());
    for (std::size_t i = 1; i < stored.size(); ++i) {
      binding.overlays.push_back(show(layers[i], *stored[i]));
    }
  }
  return reuse::economyOf(map);
}

}  // namespace

std::vector<std::filesystem::path> exportRun(RunParts& parts, const RunOptions& options,
                                             RunSummary& summary) {
  std::vector<std::filesystem::path> written;
  const auto file = [&](const char* name) { return written.emplace_back(options.out_dir / name); };
  // The mesh is written even when the source ended abnormally, so work is kept.
  fusion::SurfaceMesh mesh = parts.surface.take(summary.loops);
  const std::filesystem::path earlier_mesh = options.out_dir / "map" / "mesh.ply";
  if (options.continue_map && summary.tracking.continued_map_found_at_frame &&
      std::filesystem::is_regular_file(earlier_mesh)) {
    try {
      // Two voxels: within them the sessions' surfaces are one surface.
      mesh = fusion::mergeSurfaces(fusion::readPly(earlier_mesh), mesh,
                                   2.0 * parts.integration.map().config().voxel_size_m);
    } catch (const core::Error& e) {
      spdlog::error("mesh.ply holds this session's surface only: {}", e.what());
    }
  }
  summary.exported.mesh_vertices = mesh.vertices.size();
  fusion::writePly(mesh, file("mesh.ply"));
  const planes::PatchMap& patches = parts.planes.map();
  parts.bitmaps.flush();
  planes::TextureBindings textures =
      texture::currentBindings(parts.bitmaps.written(), patches, options.out_dir);
  DatabaseFigures& database = summary.database;
  database.location = parts.store->location();
  database.server_link = parts.store->serverLink();
  database.run_id = parts.run_id;
  for (const auto& [patch, layers] : parts.commit.instances()) database.instances += layers.size();
  summary.economy =
      bindMapTextures(*parts.store, parts.commit, parts.catalog, options.out_dir, textures);
  BitmapFigures& bitmaps = summary.bitmaps;
  for (const auto& [id, binding] : textures) {
    bitmaps.bitmaps += 1;
    bitmaps.texels_observed += binding.observed;
    bitmaps.texels_inpainted += binding.inpainted;
    bitmaps.bytes += 3 * static_cast<std::size_t>(binding.width) * binding.height;
  }
  if (parts.bitmaps.areaBuiltM2() > 0.0) {
    bitmaps.ms_per_m2 = parts.bitmaps.timer().totalMs() / parts.bitmaps.areaBuiltM2();
  }
  map_export::writePatchesObj(patches, file("patches.obj"), textures);
  // The map users open: patches triangulated with their holes, one material per texture.
  const map_export::MapModel map_model =
      map_export::buildMapModel(patches, textures, options.residual ? &mesh : nullptr);
  map_export::writeMapObj(map_model, file("map.obj"));
  map_export::writeMapGlb(map_model, options.out_dir, file("map.glb"));
  summary.exported.map_triangles = map_model.triangleCount();
  map_export::writePatchesJson(patches, file("patches.json"), textures);
  return written;
}

}  // namespace tessera::pipeline::internal
