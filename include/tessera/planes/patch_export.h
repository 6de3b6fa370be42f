#pragma once
// The finalized patches as files a user (or `tessera eval`) can open: an OBJ of untextured
// polygons, and a JSON with each patch's plane, frame and outline.
#include <filesystem>

#include "tessera/planes/patch_map.h"

namespace tessera::planes {

// One OBJ object per finalized patch ("patch_<id>_v<version>"): faces cover its closed
// occupancy grid (one quad per run of cells in a row, so holes stay open) and line elements
// trace its simplified outline and holes. Throws core::Error naming the file if writing fails.
void writePatchesObj(const PatchMap& map, const std::filesystem::path& path);

// patches.json: {"format": "tessera patches 1", "cell_m": ..., "patches": [{"id", "version",
// "normal", "offset_m", "origin", "u_axis", "v_axis", "area_m2", "colour_samples",
// "outline": [{"outer": [[u, v], ...], "holes": [[[u, v], ...], ...]}]}]}, finalized only.
void writePatchesJson(const PatchMap& map, const std::filesystem::path& path);

}  // namespace tessera::planes
