#include "tessera/planes/texture_binding.h"

#include <algorithm>
#include <array>
#include <utility>

namespace tessera::planes {

const TextureBinding* currentTexture(const Patch& patch, const TextureBindings& textures) {
  const auto it = textures.find(patch.id);
  return it != textures.end() && it->second.version == patch.version ? &it->second : nullptr;
}

Eigen::Vector2d textureCoordinates(const TextureBinding& texture, double u, double v, bool clamp) {
  const Eigen::Vector2d d = Eigen::Vector2d(u, v) - texture.origin_uv;
  if (const auto& shown = texture.map_texture) {
    // Pixel-centre coordinates on the patch's grid, through the instance, back to corners.
    const Eigen::Vector2d texel(d.dot(texture.x_axis) / texture.texel_m - 0.5,
                                d.dot(texture.y_axis) / texture.texel_m - 0.5);
    const Eigen::Vector2d frame = shown->transform.apply(texel);
    if (shown->lattice) {  // lattice coordinates: the image spans one cell, [0, 1) each way
      const Eigen::Vector2d c = shown->lattice->coordinatesOf(frame);
      return {c.x() + 0.5 / shown->width, 1.0 - (c.y() + 0.5 / shown->height)};
    }
    const Eigen::Vector2d q = frame + Eigen::Vector2d(0.5, 0.5);
    const double s = q.x() / shown->width, t = 1.0 - q.y() / shown->height;
    if (shown->tiled || !clamp) return {s, t};
    return {std::clamp(s, 0.0, 1.0), std::clamp(t, 0.0, 1.0)};
  }
  const double s = d.dot(texture.x_axis) / texture.texel_m / texture.width;
  const double t = 1.0 - d.dot(texture.y_axis) / texture.texel_m / texture.height;
  if (!clamp) return {s, t};
  return {std::clamp(s, 0.0, 1.0), std::clamp(t, 0.0, 1.0)};
}

OverlayQuad overlayQuad(const TextureBinding& texture, const MapTexture& overlay) {
  const core::Similarity2 texture_to_patch = overlay.transform.inverse();
  const double w = overlay.width, h = overlay.height;
  // Texture pixel corners, and their OBJ texture coordinates (t up).
  const std::array<Eigen::Vector2d, 4> corners{
      Eigen::Vector2d(-0.5, -0.5), {w - 0.5, -0.5}, {w - 0.5, h - 0.5}, {-0.5, h - 0.5}};
  OverlayQuad quad;
  quad.st = {Eigen::Vector2d(0, 1), {1, 1}, {1, 0}, {0, 0}};
  for (std::size_t i = 0; i < 4; ++i) {
    const Eigen::Vector2d texel = texture_to_patch.apply(corners[i]) + Eigen::Vector2d(0.5, 0.5);
    quad.uv[i] = texture.origin_uv +
                 texture.texel_m * (texel.x() * texture.x_axis + texel.y() * texture.y_axis);
  }
  // Clockwise in (u, v), as the patch's faces: the face's normal is -n.
  const Eigen::Vector2d a = quad.uv[1] - quad.uv[0], b = quad.uv[3] - quad.uv[0];
  if (a.x() * b.y() - a.y() * b.x() > 0.0) {
    std::swap(quad.uv[1], quad.uv[3]);
    std::swap(quad.st[1], quad.st[3]);
  }
  return quad;
}

}  // namespace tessera::planes
