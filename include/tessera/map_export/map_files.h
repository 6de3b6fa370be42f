#pragma once
// The map as files that common tools open: Wavefront OBJ with its MTL, and binary glTF 2.0.
#include <filesystem>

#include "tessera/map_export/map_model.h"

namespace tessera::map_export {

// OUT/map.obj and map.mtl: one material per texture image (shared by every patch that shows
// it; pattern tiles repeat, other images clamp), the residual's vertex colours as OBJ's
// "v x y z r g b". Image paths are relative to `obj_path`'s folder. Throws core::Error naming
// the file when it cannot be written.
void writeMapObj(const MapModel& model, const std::filesystem::path& obj_path);

// A binary glTF 2.0 file with the images embedded (read from `images_dir`): REPEAT samplers
// for pattern tiles, CLAMP_TO_EDGE for the rest, texel alpha as MASK. Throws core::Error naming
// the file (or the missing image) when it cannot be written.
void writeMapGlb(const MapModel& model, const std::filesystem::path& images_dir,
                 const std::filesystem::path& glb_path);

}  // namespace tessera::map_export
