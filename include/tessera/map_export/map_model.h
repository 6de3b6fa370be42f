#pragma once
// The finished map as a renderer-ready model: one textured object per finalized patch (its
// outline triangulated with its holes), one per overlay, and optionally the non-planar rest of
// the TSDF surface, vertex-coloured. The OBJ and glTF writers (map_files.h) write this model.
#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "tessera/fusion/tsdf_map.h"
#include "tessera/planes/patch_map.h"
#include "tessera/planes/texture_binding.h"

namespace tessera::map_export {

// A texture image as the map uses it, or a plain colour when `image` is empty.
struct MapMaterial {
  std::string name;     // "texture_<id>" (a database texture), "patch_<id>" or "untextured"
  std::string image;    // RGBA PNG, relative to the output folder
  bool repeat = false;  // a pattern tile: texture coordinates beyond [0, 1] repeat it
  Eigen::Vector3d colour{0.7, 0.7, 0.7};  // without an image
};

struct MapObject {
  std::string name;
  std::optional<std::size_t> material;     // index into MapModel::materials
  std::vector<Eigen::Vector3d> positions;  // world, metres
  // Per vertex, OBJ convention: s right, t up, the image spanning [0, 1] (or one lattice cell).
  std::vector<Eigen::Vector2d> uvs;
  std::vector<Eigen::Vector3d> colours;  // per vertex, [0, 1]; the residual only
  std::vector<std::array<std::uint32_t, 3>> triangles;
};

struct MapModel {
  std::vector<MapMaterial> materials;
  std::vector<MapObject> objects;
  std::size_t triangleCount() const;
};

struct ResidualOptions {
  // A TSDF triangle belongs to a patch (and is left out) when its corners lie this close to
  // the patch's plane, inside the patch's occupied cells.
  double plane_distance_m = 0.02;
};

// The finalized patches with the textures `textures` binds to them (map_export::writePatchesObj's
// bindings), their overlays, and, when `residual` is given, the part of that surface no patch
// covers as the object "residual".
MapModel buildMapModel(const planes::PatchMap& map, const planes::TextureBindings& textures,
                       const fusion::SurfaceMesh* residual = nullptr,
                       const ResidualOptions& options = {});

// Triangles covering a polygon with holes, (u, v) corners by index into `vertices` (the
// polygon's and holes' vertices, plus any where constraints cross). Empty for a degenerate
// polygon.
struct PlanarTriangles {
  std::vector<Eigen::Vector2d> vertices;
  std::vector<std::array<std::uint32_t, 3>> triangles;
};
PlanarTriangles triangulatePolygon(const planes::OutlinePart& part);

}  // namespace tessera::map_export
