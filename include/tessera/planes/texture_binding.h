#pragma once
// The texture a finalized patch shows: its own bitmap or a database texture, and where it lies
// on the patch (map_export writes them into the map's files).
#include <array>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "tessera/core/lattice2.h"
#include "tessera/core/similarity2.h"
#include "tessera/planes/patch_map.h"

namespace tessera::planes {

// The database texture a patch shows in the map: its own bitmap as stored, or a texture it
// reuses. Patch texel centre (col, row) -> texture pixel centre through `transform`; a pattern
// tile repeats (texture coordinates beyond [0, 1]). A pattern with a lattice: `transform`
// maps into its texture frame, where the image is one cell of the lattice (core::Lattice2).
struct MapTexture {
  std::int64_t texture_id = 0;
  std::string image;  // RGBA PNG, relative to the output folder
  int width = 0, height = 0;
  core::Similarity2 transform;
  bool tiled = false;
  std::optional<core::Lattice2> lattice;
  bool reused = false;
  std::optional<double> psnr_db;  // fidelity of a reuse
};

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
  std::optional<MapTexture> map_texture;  // what the map shows; the bitmap itself when absent
  // Drawn on top of map_texture (a poster on a patterned wall), each where the patch's texels
  // map into its texture's rectangle.
  std::vector<MapTexture> overlays;
};
using TextureBindings = std::map<int, TextureBinding>;  // by patch id

// The texture of the patch's current version, if there is one (else none: the patch grew
// since, or was never textured).
const TextureBinding* currentTexture(const Patch& patch, const TextureBindings& textures);

// OBJ texture coordinates (s right, t up) of plane point (u, v) in what `texture` shows (its
// map texture, else its own bitmap): the image spans [0, 1], a lattice tile one cell. Clamped
// to [0, 1], unless the image repeats or `clamp` is false (then the sampler clamps).
Eigen::Vector2d textureCoordinates(const TextureBinding& texture, double u, double v,
                                   bool clamp = true);

// The quad an overlay's image covers on its patch: (u, v) corners, clockwise (the face's normal
// is -n, towards the side the camera saw), and their OBJ texture coordinates.
struct OverlayQuad {
  std::array<Eigen::Vector2d, 4> uv, st;
};
OverlayQuad overlayQuad(const TextureBinding& texture, const MapTexture& overlay);
// Overlays are drawn this far in front of their patch (towards -n), over its base texture.
constexpr double kOverlayLift_m = 0.001;

}  // namespace tessera::planes
