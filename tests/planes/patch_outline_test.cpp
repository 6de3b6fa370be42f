#include <gtest/gtest.h>

#include "tessera/planes/patch_outline.h"

namespace tessera::planes {
namespace {

// An L of 2 m x 1 m plus 1 m x 1 m in 5 cm cells, with a 30 cm square hole in its long arm.
CellSet lShapeWithHole() {
  CellSet cells;
  for (int i = 0; i < 40; ++i) {
    for (int j = 0; j < 20; ++j) {
      const bool hole = i >= 10 && i < 16 && j >= 8 && j < 14;
      if (!hole) cells.insert({i, j});
    }
  }
  for (int i = 0; i < 20; ++i) {
    for (int j = 20; j < 40; ++j) cells.insert({i, j});
  }
  return cells;
}

TEST(PatchOutline, AnLShapeWithAHoleGivesOneOuterPolygonAndOneHole) {
  const Outline outline = traceOutline(lShapeWithHole(), 0.05);
  ASSERT_EQ(outline.parts.size(), 1u);
  const OutlinePart& part = outline.parts.front();
  ASSERT_EQ(part.holes.size(), 1u);
  EXPECT_NEAR(outline.area_m2, 2.0 + 1.0 - 0.09, 1e-9);
  // Simplified to the six corners of the L and the four of the hole.
  EXPECT_EQ(part.outer.size(), 6u);
  EXPECT_EQ(part.holes.front().size(), 4u);
  // Vertices sit 1/8 of a cell inside the true boundary: areas within that margin.
  const double margin = 0.05 / 8.0;
  EXPECT_NEAR(polygonArea(part.outer), 3.0, 8.0 * margin);  // perimeter 8 m times margin
  EXPECT_NEAR(polygonArea(part.holes.front()), 0.09, 1.2 * 4 * 0.3 * margin);
  for (const Eigen::Vector2d& p : part.outer) {
    EXPECT_GE(p.x(), -margin - 1e-9);
    EXPECT_LE(p.x(), 2.0 + margin);
    EXPECT_GE(p.y(), -margin - 1e-9);
    EXPECT_LE(p.y(), 2.0 + margin);
  }
}

TEST(PatchOutline, AOneCellGapIsClosedButTwoDistantPiecesStayTwoParts) {
  CellSet cells;
  for (int i = 0; i < 20; ++i) {
    for (int j = 0; j < 10; ++j) {
      if (i != 7 || j != 4) cells.insert({i, j});     // a missing cell inside
      cells.insert({i + 40, j});                        // a second piece 1 m away
    }
  }
  const Outline outline = traceOutline(cells, 0.05);
  ASSERT_EQ(outline.parts.size(), 2u);
  EXPECT_TRUE(outline.parts[0].holes.empty());
  EXPECT_TRUE(outline.parts[1].holes.empty());
  EXPECT_NEAR(outline.area_m2, 2 * 200 * 0.0025, 1e-9);
}

TEST(PatchOutline, NoCellsGiveNoOutline) {
  const Outline outline = traceOutline({}, 0.05);
  EXPECT_TRUE(outline.parts.empty());
  EXPECT_EQ(outline.area_m2, 0.0);
}

}  // namespace
}  // namespace tessera::planes
