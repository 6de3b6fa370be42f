#pragma once
// A small CPU rasteriser for the view evaluation (docs/METRICS.md, view PSNR): renders a
// textured map (patches.obj, map.obj or map.glb with their RGBA images) or a vertex-coloured mesh
// (mesh.ply) from a camera pose into an image the size of the captured frame, with a depth buffer.
#include <filesystem>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core/mat.hpp>

#include "tessera/core/intrinsics.h"
#include "tessera/core/pose.h"

namespace tessera::eval {

// An OBJ material's image: CV_8UC4 RGBA, texels with alpha 0 covering nothing; `repeat` as
// MTL's default, off for `map_Kd -clamp on`.
struct TextureImage {
  cv::Mat rgba;
  bool repeat = true;
};

// World-space triangles, either vertex-coloured or textured (one RGBA texture per triangle).
struct RenderMesh {
  std::vector<Eigen::Vector3f> vertices;
  std::vector<Eigen::Vector3i> triangles;
  std::vector<Eigen::Vector3f> colours;  // vertex-coloured: RGB in [0, 255] per vertex
  std::vector<Eigen::Vector2f> uvs;      // textured: (s, t) per triangle corner, OBJ convention
  std::vector<int> texture_of;           // textured: per triangle, index into textures or -1
  std::vector<TextureImage> textures;
  // Textured: per triangle, index into surfaces, the OBJ object or glTF node it belongs to
  // (patch_3_v2: a patch's version), so that a view's error can be told per surface.
  std::vector<int> surface_of;
  std::vector<std::string> surfaces;
  bool textured() const { return !texture_of.empty(); }
};

// Reads an OBJ with its MTL and map_Kd images (as tessera writes patches.obj). Faces whose
// material has no image are not drawn. Throws core::Error naming the file that is missing or
// malformed.
RenderMesh readTexturedObj(const std::filesystem::path& path);

// Reads a binary glTF (as tessera writes map.glb): the triangles of every primitive whose
// material has a base colour texture, with TEXCOORD_0; a REPEAT sampler repeats. Objects
// without a texture (the vertex-coloured residual) are not drawn, as in the OBJ. Throws
// core::Error naming the file that is missing or malformed.
RenderMesh readTexturedGlb(const std::filesystem::path& path);
// readTexturedGlb for a .glb, else readTexturedObj.
RenderMesh readTexturedMap(const std::filesystem::path& path);

// Reads a vertex-coloured PLY (mesh.ply). Throws core::Error naming the file.
RenderMesh readColouredPly(const std::filesystem::path& path);

struct ViewImage {
  cv::Mat rgb;    // CV_8UC3
  cv::Mat depth;  // CV_32F, camera z in metres; 0 where nothing was drawn
  cv::Mat surface;  // CV_32S, index into RenderMesh::surfaces; -1 where none was drawn
};

// Renders `mesh` seen by a pinhole camera at T_W_C (pixel (x, y) is the ray through
// ((x - cx) / fx, (y - cy) / fy, 1), as tessera samples frames). Triangles are clipped at
// near_m, depth-tested, and their colours interpolated perspective-correctly; textures are
// sampled bilinearly over their opaque texels.
ViewImage renderView(const RenderMesh& mesh, const core::Intrinsics& intrinsics,
                     const core::Isometry& T_W_C, double near_m = 0.05);

}  // namespace tessera::eval
