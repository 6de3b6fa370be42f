#include <cmath>
#include <map>

#include <fmt/format.h>

#include "tessera/map_export/map_model.h"

namespace tessera::map_export {

namespace {

// Materials by name, each added once.
class MaterialTable {
 public:
  explicit MaterialTable(std::vector<MapMaterial>& materials) : materials_(materials) {}
  std::size_t indexOf(const MapMaterial& material) {
    const auto [it, added] = index_.try_emplace(material.name, materials_.size());
    if (added) materials_.push_back(material);
    return it->second;
  }

 private:
  std::vector<MapMaterial>& materials_;
  std::map<std::string, std::size_t> index_;
};

MapMaterial materialOf(const planes::MapTexture& shown) {
  return {fmt::format("texture_{}", shown.texture_id), shown.image, shown.tiled, {1.0, 1.0, 1.0}};
}

// The patch's outline, triangulated with its holes; texture coordinates from its binding.
MapObject patchObject(const planes::PatchMap& map, const planes::Patch& patch,
                      const planes::TextureBinding* texture, MaterialTable& materials) {
  MapObject object;
  object.name = fmt::format("patch_{}_v{}", patch.id, patch.version);
  if (texture == nullptr) {
    object.material = materials.indexOf({"untextured", "", false, {0.7, 0.7, 0.7}});
  } else if (texture->map_texture) {
    object.material = materials.indexOf(materialOf(*texture->map_texture));
  } else {
    object.material = materials.indexOf(
        {fmt::format("patch_{}", patch.id), texture->image, false, {1.0, 1.0, 1.0}});
  }
  const planes::Patch::Frame frame = patch.planeFrame();
  for (const planes::OutlinePart& part : map.outlineOf(patch).parts) {
    const PlanarTriangles planar = triangulatePolygon(part);
    const auto first = static_cast<std::uint32_t>(object.positions.size());
    for (const Eigen::Vector2d& uv : planar.vertices) {
      object.positions.push_back(frame.at(uv.x(), uv.y()));
      // Unclamped: the texture coordinates are affine in (u, v), so a triangle with a corner
      // beyond the image still maps every point right (the sampler clamps).
      object.uvs.push_back(texture != nullptr
                               ? planes::textureCoordinates(*texture, uv.x(), uv.y(), false)
                               : Eigen::Vector2d::Zero());
    }
    // The triangulation is counter-clockwise in (u, v); the faces turn to -n, the side the
    // camera saw, as in patches.obj.
    for (const auto& t : planar.triangles) {
      object.triangles.push_back({first + t[0], first + t[2], first + t[1]});
    }
  }
  return object;
}

MapObject overlayObject(const planes::Patch& patch, const planes::TextureBinding& texture,
                        const planes::MapTexture& overlay, std::size_t layer,
                        MaterialTable& materials) {
  MapObject object;
  object.name = fmt::format("patch_{}_v{}_overlay_{}", patch.id, patch.version, layer);
  object.material = materials.indexOf(materialOf(overlay));
  const planes::OverlayQuad quad = planes::overlayQuad(texture, overlay);
  const planes::Patch::Frame frame = patch.planeFrame();
  for (std::size_t i = 0; i < 4; ++i) {
    object.positions.push_back(frame.at(quad.uv[i].x(), quad.uv[i].y()) -
                               planes::kOverlayLift_m * patch.normal());
    object.uvs.push_back(quad.st[i]);
  }
  object.triangles = {{0, 1, 2}, {0, 2, 3}};
  return object;
}

// Whether X lies on a finalized patch: near its plane, in or next to one of its cells.
bool onAPatch(const Eigen::Vector3d& X, const std::vector<const planes::Patch*>& patches,
              double cell_m, double distance_m) {
  for (const planes::Patch* patch : patches) {
    if (std::abs(patch->normal().dot(X) - patch->offset()) > distance_m) continue;
    const planes::Cell c = patch->cellOf(X, cell_m);
    for (const auto& [di, dj] : {std::pair{0, 0}, {1, 0}, {-1, 0}, {0, 1}, {0, -1}}) {
      if (patch->cells.count({c.first + di, c.second + dj})) return true;
    }
  }
  return false;
}

// The surface's triangles that no finalized patch covers, vertex-coloured.
MapObject residualObject(const planes::PatchMap& map, const fusion::SurfaceMesh& surface,
                         const ResidualOptions& options) {
  std::vector<const planes::Patch*> patches;
  for (const planes::Patch& patch : map.patches()) {
    if (patch.finalized) patches.push_back(&patch);
  }
  MapObject object;
  object.name = "residual";
  std::vector<std::int64_t> kept(surface.vertices.size(), -1);
  for (const Eigen::Vector3i& t : surface.triangles) {
    const Eigen::Vector3d centroid =
        (surface.vertices[t[0]] + surface.vertices[t[1]] + surface.vertices[t[2]]) / 3.0;
    if (onAPatch(centroid, patches, map.config().cell_m, options.plane_distance_m)) continue;
    std::array<std::uint32_t, 3> corners{};
    for (int k = 0; k < 3; ++k) {
      std::int64_t& index = kept[static_cast<std::size_t>(t[k])];
      if (index < 0) {
        index = static_cast<std::int64_t>(object.positions.size());
        object.positions.push_back(surface.vertices[t[k]]);
        object.colours.push_back(surface.colors.empty() ? Eigen::Vector3d(0.7, 0.7, 0.7)
                                                        : surface.colors[t[k]]);
      }
      corners[k] = static_cast<std::uint32_t>(index);
    }
    object.triangles.push_back(corners);
  }
  return object;
}

}  // namespace

std::size_t MapModel::triangleCount() const {
  std::size_t n = 0;
  for (const MapObject& object : objects) n += object.triangles.size();
  return n;
}

MapModel buildMapModel(const planes::PatchMap& map, const planes::TextureBindings& textures,
                       const fusion::SurfaceMesh* residual, const ResidualOptions& options) {
  MapModel model;
  MaterialTable materials(model.materials);
  for (const planes::Patch& patch : map.patches()) {
    if (!patch.finalized) continue;
    const planes::TextureBinding* texture = planes::currentTexture(patch, textures);
    MapObject object = patchObject(map, patch, texture, materials);
    if (object.triangles.empty()) continue;
    model.objects.push_back(std::move(object));
    if (texture == nullptr) continue;
    for (std::size_t k = 0; k < texture->overlays.size(); ++k) {
      model.objects.push_back(
          overlayObject(patch, *texture, texture->overlays[k], k + 1, materials));
    }
  }
  if (residual != nullptr) {
    MapObject object = residualObject(map, *residual, options);
    if (!object.triangles.empty()) {
      // A material of its own: in an OBJ a face without `usemtl` would take the one before
      // it. White, so that the vertex colours show as they are.
      object.material = materials.indexOf({"vertex_colours", "", false, {1.0, 1.0, 1.0}});
      model.objects.push_back(std::move(object));
    }
  }
  return model;
}

}  // namespace tessera::map_export
