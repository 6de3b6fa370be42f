// A pattern stored from one patch is found in another through NCC, at the other's phase and
// quarter turn, and renders that patch faithfully: the phase travels in the instance.
#include <gtest/gtest.h>
#include <opencv2/core.hpp>

#include "pattern/pattern_test_support.h"
#include "tessera/match/match_cascade.h"
#include "tessera/pattern/pattern_extractor.h"

namespace tessera::pattern {
namespace {

TEST(PatternReuse, ASecondPatchFindsTheStoredTileAtItsOwnPhaseAndTurn) {
  const cv::Mat tile = testing::randomTile(22, 15, 21);
  const core::Lattice2 truth{{22.0, 0.0}, {11.0, 15.0}};  // running-bond-like shear
  const cv::Mat first = testing::tiling(tile, truth, 220, 170, {1.0, 0.0, 3.0, 5.0});
  const PatternAnalysis analysis = analysePattern(first, {});
  ASSERT_TRUE(analysis.pattern) << analysis.reason;
  const Pattern& found = *analysis.pattern;

  const match::MatchConfig config;
  match::MemoryCatalog catalog(config.ccv);
  catalog.add(match::patternTexture(1, found.tile_rgb, found.tile_mask, found.lattice, config));

  // The second patch: another part of the wall, its grid turned a quarter against the first.
  const core::Similarity2 second_to_frame{0.0, 1.0, 61.7, -13.2};
  const cv::Mat second = testing::tiling(tile, truth, 160, 190, second_to_frame);
  const match::MatchCascade cascade(config);
  const match::MatchDecision decision =
      cascade.match(match::describeTexture(second, {}, config), catalog);
  ASSERT_TRUE(decision.match) << (decision.verdicts.empty() ? "no candidate"
                                                            : decision.verdicts.front().reason);
  EXPECT_EQ(decision.match->method, "ncc");
  EXPECT_GT(decision.match->psnr_db, 30.0);

  const auto stored = catalog.load(1);
  const match::Rendered shown =
      match::renderStored(*stored, *decision.match->transform, second.cols, second.rows);
  const match::Fidelity fidelity = match::measureFidelity(second, {}, shown);
  EXPECT_GT(fidelity.psnr_db, 30.0);
  EXPECT_EQ(fidelity.coverage, 1.0);
}

TEST(PatternReuse, AnUnrelatedPatternIsNotReused) {
  const match::MatchConfig config;
  match::MemoryCatalog catalog(config.ccv);
  const cv::Mat tile = testing::randomTile(20, 20, 1);
  catalog.add(match::patternTexture(1, tile, {}, {{20.0, 0.0}, {0.0, 20.0}}, config));
  const cv::Mat other =
      testing::tiling(testing::randomTile(20, 20, 2), {{20.0, 0.0}, {0.0, 20.0}}, 160, 160);
  const match::MatchDecision decision =
      match::MatchCascade(config).match(match::describeTexture(other, {}, config), catalog);
  EXPECT_FALSE(decision.match);
}

}  // namespace
}  // namespace tessera::pattern
