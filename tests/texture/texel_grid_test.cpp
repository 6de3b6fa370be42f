#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include "tessera/texture/texel_grid.h"

namespace tessera::texture {
namespace {

planes::Outline outlineOf(planes::Polygon2 outer, std::vector<planes::Polygon2> holes = {}) {
  planes::Outline outline;
  outline.parts.push_back({std::move(outer), std::move(holes)});
  return outline;
}

// Where (u, v) falls in the grid, as the texel's mask value.
std::uint8_t maskAt(const TexelGrid& grid, const Eigen::Vector2d& uv) {
  const Eigen::Vector2d d = uv - grid.origin_uv;
  const int col = static_cast<int>(std::floor(d.dot(grid.x_axis) / grid.texel_m));
  const int row = static_cast<int>(std::floor(d.dot(grid.y_axis) / grid.texel_m));
  if (col < 0 || row < 0 || col >= grid.width || row >= grid.height) return 0;
  return grid.mask.at<std::uint8_t>(row, col);
}

TEST(TexelGrid, ARotatedRectangleGetsATightGridAlongItsOwnSides) {
  // A 2 m x 1 m rectangle turned 30 degrees in the patch plane.
  const Eigen::Rotation2Dd turn(30.0 * M_PI / 180.0);
  planes::Polygon2 corners;
  for (const auto& c : {Eigen::Vector2d(0, 0), Eigen::Vector2d(2, 0), Eigen::Vector2d(2, 1),
                        Eigen::Vector2d(0, 1)}) {
    corners.push_back(Eigen::Vector2d(0.3, -0.2) + turn * c);
  }
  const planes::Outline outline = outlineOf(corners);
  const TexelGrid grid = principalAxisGrid(outline, 0.01);
  EXPECT_NEAR(std::abs(grid.x_axis.dot(turn * Eigen::Vector2d::UnitX())), 1.0, 1e-9);
  EXPECT_NEAR(grid.width, 200, 1);
  EXPECT_NEAR(grid.height, 100, 1);
  // Every texel of the tight grid is inside, but for the rounded edge.
  EXPECT_GT(cv::countNonZero(grid.mask), 0.98 * 20000);

  const TexelGrid minimum = minimumAreaGrid(outline, 0.01);
  EXPECT_NEAR(static_cast<double>(minimum.texels()), 20000, 400);
  EXPECT_GT(cv::countNonZero(minimum.mask), 0.98 * 20000);

  const GridSizes sizes = compareGrids(outline, 0.01);
  EXPECT_NEAR(static_cast<double>(sizes.principal_axes), 20000, 400);
  EXPECT_NEAR(static_cast<double>(sizes.minimum_area), 20000, 400);
  // The axis-aligned box of the turned rectangle: (2 cos 30 + sin 30) x (2 sin 30 + cos 30).
  EXPECT_NEAR(static_cast<double>(sizes.axis_aligned), 223.2 * 186.6, 500);
}

TEST(TexelGrid, AnLShapedPatchWithAHoleMasksTheHoleAndTheNotch) {
  const planes::Polygon2 l_shape = {{0, 0}, {2, 0}, {2, 1}, {1, 1}, {1, 2}, {0, 2}};
  const planes::Polygon2 hole = {{0.5, 0.4}, {0.8, 0.4}, {0.8, 0.7}, {0.5, 0.7}};
  const TexelGrid grid = principalAxisGrid(outlineOf(l_shape, {hole}), 0.01);
  // 3 m^2 minus the 0.09 m^2 hole, at 1 cm texels. cv::fillPoly keeps the texels its edges
  // pass through, about half a texel along the 9.2 m of boundary (measured: 29411).
  EXPECT_GE(cv::countNonZero(grid.mask), 29100);
  EXPECT_LE(cv::countNonZero(grid.mask), 29100 + 920);
  EXPECT_EQ(maskAt(grid, {0.25, 0.25}), 255);   // in the L
  EXPECT_EQ(maskAt(grid, {1.75, 0.5}), 255);    // in its long arm
  EXPECT_EQ(maskAt(grid, {0.5, 1.75}), 255);    // in its other arm
  EXPECT_EQ(maskAt(grid, {0.65, 0.55}), 0);     // in the hole
  EXPECT_EQ(maskAt(grid, {1.5, 1.5}), 0);       // in the notch of the L
  EXPECT_EQ(maskAt(grid, {0.515, 0.55}), 0);    // 1.5 cm inside the hole's edge
  EXPECT_EQ(maskAt(grid, {0.485, 0.55}), 255);  // 1.5 cm outside it
}

TEST(TexelGrid, TheDefaultTexelIsThePixelFootprint) {
  EXPECT_NEAR(pixelFootprintTexel(2.0, 525.0), 0.00381, 1e-5);
}

}  // namespace
}  // namespace tessera::texture
