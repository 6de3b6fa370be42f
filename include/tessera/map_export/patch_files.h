#pragma once
// The finalized patches as files a user (or `tessera eval`) can open: an OBJ of textured
// polygons (patches.obj), and a JSON with each patch's plane, frame, outline and texture.
#include <filesystem>

#include "tessera/planes/patch_map.h"
#include "tessera/planes/texture_binding.h"

namespace tessera::map_export {

// One OBJ object per finalized patch ("patch_<id>_v<version>"): faces cover its closed
// occupancy grid (one quad per run of cells in a row, so holes stay open) and line elements
// trace its simplified outline and holes. A patch with a texture of its current version gets
// texture coordinates and a material "patch_<id>" whose map_Kd is its image, in a .mtl file
// next to the OBJ; a patch with a map texture uses the material "texture_<id>" of that database
// texture instead, shared by every patch that reuses it, with texture coordinates carried
// through the instance's transform. Each overlay is one more object ("..._overlay_<k>"): the
// quad its texture covers, 1 mm in front of the patch. Throws core::Error naming the file if
// writing fails.
void writePatchesObj(const planes::PatchMap& map, const std::filesystem::path& path,
                     const planes::TextureBindings& textures = {});

// patches.json: {"format": "tessera patches 1", "cell_m": ..., "patches": [{"id", "plane" (the
// id of the plane's first tile; tiles of one plane share it and its frame), "tile": [i, j],
// "version", "normal", "offset_m", "origin", "u_axis", "v_axis", "area_m2", "colour_samples",
// "outline": [{"outer": [[u, v], ...], "holes": [[[u, v], ...], ...]}], "texture": {"image",
// "state_image", "texel_m", "origin_uv", "x_axis", "y_axis", "width", "height", "observed",
// "inpainted"} or null, "instance": {"texture_id", "image", "width", "height", "transform":
// [a, b, tx, ty], "tiled", "lattice": [v1x, v1y, v2x, v2y] or null, "reused", "psnr_db",
// "overlays": [{"texture_id", "image", "width", "height", "transform", "reused", "psnr_db"}]}
// or null}]}, finalized only.
void writePatchesJson(const planes::PatchMap& map, const std::filesystem::path& path,
                      const planes::TextureBindings& textures = {});

}  // namespace tessera::map_export
