#include "tessera/map_export/patch_files.h"

#include <algorithm>
#include <array>
#include <fstream>
#include <map>
#include <set>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "tessera/core/error.h"
#include "tessera/core/output_file.h"

namespace tessera::map_export {

using planes::MapTexture;
using planes::Outline;
using planes::OutlinePart;
using planes::OverlayQuad;
using planes::Patch;
using planes::PatchMap;
using planes::Polygon2;
using planes::TextureBinding;
using planes::TextureBindings;

namespace {

nlohmann::json polygonJson(const Polygon2& polygon) {
  nlohmann::json points = nlohmann::json::array();
  for (const Eigen::Vector2d& p : polygon) points.push_back({p.x(), p.y()});
  return points;
}

nlohmann::json vectorJson(const Eigen::Vector3d& v) { return {v.x(), v.y(), v.z()}; }
nlohmann::json vectorJson(const Eigen::Vector2d& v) { return {v.x(), v.y()}; }

}  // namespace

namespace {

// An overlay as its own object: the quad its texture's rectangle covers on the patch, lifted
// planes::kOverlayLift_m towards the side the camera saw (-n) so that it is drawn over the pattern.
// Returns the vertex count after it.
std::size_t writeOverlay(std::ofstream& out, const Patch& patch, const Patch::Frame& frame,
                         const TextureBinding& texture, const MapTexture& overlay,
                         std::size_t layer, std::size_t vertices) {
  const OverlayQuad quad = planes::overlayQuad(texture, overlay);
  out << fmt::format("o patch_{}_v{}_overlay_{}\nusemtl texture_{}\n", patch.id, patch.version,
                     layer, overlay.texture_id);
  for (std::size_t i = 0; i < 4; ++i) {
    const Eigen::Vector3d X =
        frame.at(quad.uv[i].x(), quad.uv[i].y()) - planes::kOverlayLift_m * patch.normal();
    out << fmt::format("v {:.4f} {:.4f} {:.4f}\nvt {:.5f} {:.5f}\n", X.x(), X.y(), X.z(),
                       quad.st[i].x(), quad.st[i].y());
  }
  const std::size_t f = vertices + 1;
  out << fmt::format("f {0}/{0} {1}/{1} {2}/{2} {3}/{3}\n", f, f + 1, f + 2, f + 3);
  return vertices + 4;
}

std::string materialOf(const Patch& patch, const TextureBinding& texture) {
  return texture.map_texture ? fmt::format("texture_{}", texture.map_texture->texture_id)
                             : fmt::format("patch_{}", patch.id);
}

void writeMaterials(const PatchMap& map, const TextureBindings& textures,
                    const std::filesystem::path& path) {
  std::ofstream out = core::createOutputFile(path);
  out << "# tessera patch textures\n";
  // Patches without a bitmap use this plain material: an OBJ's material carries over from one
  // object to the next, so each patch names its own.
  out << "newmtl untextured\nKa 1 1 1\nKd 0.7 0.7 0.7\nKs 0 0 0\nillum 1\n\n";
  std::set<std::int64_t> written;
  for (const Patch& patch : map.patches()) {
    const TextureBinding* texture =
        patch.finalized ? planes::currentTexture(patch, textures) : nullptr;
    if (texture == nullptr) continue;
    if (texture->map_texture) {
      std::vector<const MapTexture*> layers{&*texture->map_texture};
      for (const MapTexture& overlay : texture->overlays) layers.push_back(&overlay);
      for (const MapTexture* shown : layers) {
        if (!written.insert(shown->texture_id).second) continue;
        // A pattern tile repeats (MTL's default wrap); anything else stops at its edges.
        const char* wrap = shown->tiled ? "" : "-clamp on ";
        out << fmt::format(
            "newmtl texture_{}\nKa 1 1 1\nKd 1 1 1\nKs 0 0 0\nillum 1\nmap_Kd {}{}\nmap_d "
            "{}{}\n\n",
            shown->texture_id, wrap, shown->image, wrap, shown->image);
      }
      continue;
    }
    out << fmt::format(
        "newmtl patch_{}\nKa 1 1 1\nKd 1 1 1\nKs 0 0 0\nillum 1\nmap_Kd -clamp on {}\n"
        "map_d -clamp on {}\n\n",
        patch.id, texture->image, texture->image);
  }
  core::finishOutputFile(out, path);
}

}  // namespace

void writePatchesObj(const PatchMap& map, const std::filesystem::path& path,
                     const TextureBindings& textures) {
  std::filesystem::path materials = path;
  materials.replace_extension(".mtl");
  writeMaterials(map, textures, materials);
  std::ofstream out = core::createOutputFile(path);
  out << "# tessera finalized planar patches\n";
  out << "mtllib " << materials.filename().string() << '\n';
  const double cell = map.config().cell_m;
  std::size_t vertices = 0;
  for (const Patch& patch : map.patches()) {
    if (!patch.finalized) continue;
    const Outline outline = map.outlineOf(patch);
    const Patch::Frame frame = patch.planeFrame();
    const TextureBinding* texture = planes::currentTexture(patch, textures);
    out << fmt::format("o patch_{}_v{}\n", patch.id, patch.version);
    out << "usemtl " << (texture != nullptr ? materialOf(patch, *texture) : "untextured") << '\n';
    // Every vertex gets a texture coordinate (0, 0 on untextured patches), so that vertex and
    // texture-coordinate indices stay equal through the file.
    auto vertex = [&](double u, double v) {
      const Eigen::Vector3d X = frame.at(u, v);
      const Eigen::Vector2d st =
          texture != nullptr ? planes::textureCoordinates(*texture, u, v) : Eigen::Vector2d::Zero();
      out << fmt::format("v {:.4f} {:.4f} {:.4f}\nvt {:.5f} {:.5f}\n", X.x(), X.y(), X.z(), st.x(),
                         st.y());
      return ++vertices;
    };
    // One quad per occupied cell, its corners shared with the neighbouring cells' quads: the
    // surface is watertight. (Quads per run of cells left T-junctions, whose rounded vertices
    // opened hairline cracks a render shows.)
    std::map<std::pair<int, int>, std::size_t> corners;
    auto corner = [&](int i, int j) {
      const auto [it, added] = corners.try_emplace({i, j}, 0);
      if (added)
        it->second =
            vertex((outline.first_cell.first + i) * cell, (outline.first_cell.second + j) * cell);
      return it->second;
    };
    for (int r = 0; r < outline.grid.rows; ++r) {
      const auto* row = outline.grid.ptr<std::uint8_t>(r);
      for (int c = 0; c < outline.grid.cols; ++c) {
        if (row[c] == 0) continue;
        const std::size_t a = corner(c, r), b = corner(c + 1, r), d = corner(c + 1, r + 1),
                          e = corner(c, r + 1);
        // Clockwise in (u, v): the face's normal is -n, towards the side the camera saw.
        out << fmt::format("f {0}/{0} {1}/{1} {2}/{2} {3}/{3}\n", a, e, d, b);
      }
    }
    auto polyline = [&](const Polygon2& polygon) {
      const std::size_t first = vertices + 1;
      for (const Eigen::Vector2d& p : polygon) vertex(p.x(), p.y());
      out << 'l';
      for (std::size_t i = 0; i < polygon.size(); ++i) out << ' ' << first + i;
      out << ' ' << first << '\n';
    };
    for (const OutlinePart& part : outline.parts) {
      polyline(part.outer);
      for (const Polygon2& hole : part.holes) polyline(hole);
    }
    if (texture == nullptr) continue;
    for (std::size_t k = 0; k < texture->overlays.size(); ++k) {
      vertices = writeOverlay(out, patch, frame, *texture, texture->overlays[k], k + 1, vertices);
    }
  }
  core::finishOutputFile(out, path);
}

void writePatchesJson(const PatchMap& map, const std::filesystem::path& path,
                      const TextureBindings& textures) {
  nlohmann::json patches = nlohmann::json::array();
  for (const Patch& patch : map.patches()) {
    if (!patch.finalized) continue;
    const Outline outline = map.outlineOf(patch);
    const Patch::Frame frame = patch.planeFrame();
    nlohmann::json parts = nlohmann::json::array();
    for (const OutlinePart& part : outline.parts) {
      nlohmann::json holes = nlohmann::json::array();
      for (const Polygon2& hole : part.holes) holes.push_back(polygonJson(hole));
      parts.push_back({{"outer", polygonJson(part.outer)}, {"holes", holes}});
    }
    nlohmann::json texture_json = nullptr;
    if (const TextureBinding* texture = planes::currentTexture(patch, textures)) {
      texture_json = {{"image", texture->image},
                      {"state_image", texture->state_image},
                      {"texel_m", texture->texel_m},
                      {"origin_uv", vectorJson(texture->origin_uv)},
                      {"x_axis", vectorJson(texture->x_axis)},
                      {"y_axis", vectorJson(texture->y_axis)},
                      {"width", texture->width},
                      {"height", texture->height},
                      {"observed", texture->observed},
                      {"inpainted", texture->inpainted}};
    }
    nlohmann::json instance_json = nullptr;
    if (const TextureBinding* texture = planes::currentTexture(patch, textures);
        texture != nullptr && texture->map_texture) {
      const MapTexture& shown = *texture->map_texture;
      const core::Similarity2& s = shown.transform;
      instance_json = {
          {"texture_id", shown.texture_id},
          {"image", shown.image},
          {"width", shown.width},
          {"height", shown.height},
          {"transform", {s.a, s.b, s.tx, s.ty}},
          {"tiled", shown.tiled},
          {"lattice", shown.lattice ? nlohmann::json{shown.lattice->v1.x(), shown.lattice->v1.y(),
                                                     shown.lattice->v2.x(), shown.lattice->v2.y()}
                                    : nlohmann::json(nullptr)},
          {"reused", shown.reused},
          {"psnr_db", shown.psnr_db ? nlohmann::json(*shown.psnr_db) : nullptr}};
      nlohmann::json overlays = nlohmann::json::array();
      for (const MapTexture& overlay : texture->overlays) {
        const core::Similarity2& o = overlay.transform;
        overlays.push_back(
            {{"texture_id", overlay.texture_id},
             {"image", overlay.image},
             {"width", overlay.width},
             {"height", overlay.height},
             {"transform", {o.a, o.b, o.tx, o.ty}},
             {"reused", overlay.reused},
             {"psnr_db", overlay.psnr_db ? nlohmann::json(*overlay.psnr_db) : nullptr}});
      }
      instance_json["overlays"] = overlays;
    }
    patches.push_back({{"id", patch.id},
                       {"plane", patch.plane},
                       {"tile", {patch.tile.first, patch.tile.second}},
                       {"version", patch.version},
                       {"normal", vectorJson(patch.normal())},
                       {"offset_m", patch.offset()},
                       {"origin", vectorJson(frame.origin)},
                       {"u_axis", vectorJson(frame.u_axis)},
                       {"v_axis", vectorJson(frame.v_axis)},
                       {"area_m2", outline.area_m2},
                       {"colour_samples", patch.samples->size()},
                       {"outline", parts},
                       {"texture", texture_json},
                       {"instance", instance_json}});
  }
  std::ofstream out = core::createOutputFile(path);
  out << nlohmann::json{{"format", "tessera patches 1"},
                        {"cell_m", map.config().cell_m},
                        {"patches", patches}}
             .dump(1)
      << '\n';
  core::finishOutputFile(out, path);
}

}  // namespace tessera::map_export
