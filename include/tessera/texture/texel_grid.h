#pragma once
// The texel grid of a finalized patch: a rectangle of square texels laid over its outline,
// aligned to the outline's principal axes (PCA of its vertices, as the published method has
// it), covering the outline's bounding box in that frame. Texels outside the outline are
// masked out; they never get made-up colour.
#include <Eigen/Core>
#include <opencv2/core/mat.hpp>

#include "tessera/planes/patch_map.h"
#include "tessera/planes/patch_outline.h"

namespace tessera::texture {

struct TexelGrid {
  double texel_m = 0.005;
  // Texel (col, row) covers [origin + col t x_axis + row t y_axis, + t x_axis + t y_axis), in
  // the patch's (u, v) plane coordinates.
  Eigen::Vector2d origin_uv = Eigen::Vector2d::Zero();
  Eigen::Vector2d x_axis = Eigen::Vector2d::UnitX();  // unit, in (u, v)
  Eigen::Vector2d y_axis = Eigen::Vector2d::UnitY();
  int width = 0, height = 0;
  cv::Mat mask;  // CV_8U, height x width: 255 where the texel centre lies inside the outline

  Eigen::Vector2d uvOf(double col, double row) const {
    return origin_uv + texel_m * (col * x_axis + row * y_axis);
  }
  std::size_t texels() const { return static_cast<std::size_t>(width) * height; }
};

// The grid aligned to the principal axes of the outline's vertices (outer polygons and holes).
TexelGrid principalAxisGrid(const planes::Outline& outline, double texel_m);

// The grid along the outer vertices' minimum-area rectangle (OpenCV's rotating calipers).
TexelGrid minimumAreaGrid(const planes::Outline& outline, double texel_m);

// Texel counts of the three ways to lay a rectangle over the outline, for the same texel size:
// principal axes (what tessera uses), the patch's own (u, v) axes, and the minimum-area
// rectangle (OpenCV's rotating calipers over the outer vertices).
struct GridSizes {
  std::size_t principal_axes = 0;
  std::size_t axis_aligned = 0;
  std::size_t minimum_area = 0;
};
GridSizes compareGrids(const planes::Outline& outline, double texel_m);

// Default texel size: the footprint of one pixel at the given viewing distance, distance / fx
// (at 2 m and fx 525: 3.8 mm), so that the texture is as sharp as the sensor saw it.
double pixelFootprintTexel(double viewing_distance_m, double fx);

}  // namespace tessera::texture
