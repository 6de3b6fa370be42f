// The economy of a small map worked out by hand: shared textures count once, a patch shown
// through no texture counts its own bitmap on both sides, overlays and matched kinds count per
// layer.
#include "tessera/reuse/map_economy.h"

#include <gtest/gtest.h>

namespace tessera::reuse {
namespace {

TEST(MapEconomy, SharedTexturesCountOnceAndOwnBitmapsOnBothSides) {
  std::map<int, ShownPatch> map;
  map[1] = {1000, {{7, 900, false, false, std::nullopt}}};  // stored its own texture 7
  map[2] = {1200, {{7, 900, false, true, 31.5}}};           // reuses texture 7
  // A pattern tile stored before, with an overlay of its own.
  map[3] = {4000, {{8, 100, true, true, 29.0}, {9, 300, false, false, std::nullopt}}};
  map[4] = {500, {}};  // not committed: the map shows its bitmap

  const Economy economy = economyOf(map);
  EXPECT_EQ(economy.textured_patches, 3u);
  EXPECT_EQ(economy.reuses, 2u);
  EXPECT_EQ(economy.textures_matched, 1u);
  EXPECT_EQ(economy.patterns_matched, 1u);
  EXPECT_EQ(economy.overlays, 1u);
  EXPECT_EQ(economy.pixels_before, 1000u + 1200u + 4000u + 500u);
  EXPECT_EQ(economy.pixels_after, 900u + 100u + 300u + 500u);
  EXPECT_EQ(economy.shown_psnrs_db, (std::vector<double>{31.5, 29.0}));
}

TEST(MapEconomy, EmptyMapHasNothing) {
  const Economy economy = economyOf({});
  EXPECT_EQ(economy.pixels_before, 0u);
  EXPECT_EQ(economy.pixels_after, 0u);
  EXPECT_EQ(economy.textured_patches, 0u);
}

}  // namespace
}  // namespace tessera::reuse
