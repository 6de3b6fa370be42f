#pragma once
// The finalized patches as files a user (or `tessera eval`) can open: an OBJ of untextured
// polygons, and a JSON with each patch's plane, frame and outline.
#include <cstddef>
#include <filesystem>
#include <map>
#include <string>

#include "tessera/planes/patch_map.h"

namespace tessera::planes {

// Where a patch's bitmap lies on the patch: texel (col, row) covers origin_uv + texel_m (col
// x_axis + row y_axis) and the next texel_m along each axis, in the patch's (u, v) frame.
struct TextureBinding {
  int version = 0;          // the patch version the bitmap was built from
  std::string image;        // RGBA PNG, relative to the output folder
  std::string state_image;  // grey PNG: 255 observed, 128 inpainted, 0 empty
  double texel_m = 0.0;
  Eigen::Vector2d origin_uv = Eigen::Vector2d::Zero();
  Eigen::Vector2d x_axis = Eigen::Vector2d::UnitX(), y_axis = Eigen::Vector2d::UnitY();
  int width = 0, height = 0;
  std::size_t observed = 0, inpainted = 0;
};
using TextureBindings = std::map<int, TextureBinding>;  // by patch id

// One OBJ object per finalized patch ("patch_<id>_v<version>"): faces cover its closed
// occupancy grid (one quad per run of cells in a row, so holes stay open) and line elements
// trace its simplified outline and holes. A patch with a texture of its current version gets
// texture coordinates and a material "patch_<id>" whose map_Kd is its image, in a .mtl file
// next to the OBJ. Throws core::Error naming the file if writing fails.
void writePatchesObj(const PatchMap& map, const std::filesystem::path& path,
                     const TextureBindings& textures = {});

// patches.json: {"format": "tessera patches 1", "cell_m": ..., "patches": [{"id", "version",
// "normal", "offset_m", "origin", "u_axis", "v_axis", "area_m2", "colour_samples",
// "outline": [{"outer": [[u, v], ...], "holes": [[[u, v], ...], ...]}], "texture": {"image",
// "state_image", "texel_m", "origin_uv", "x_axis", "y_axis", "width", "height", "observed",
// "inpainted"} or null}]}, finalized only.
void writePatchesJson(const PatchMap& map, const std::filesystem::path& path,
                      const TextureBindings& textures = {});

}  // namespace tessera::planes
