// A pattern stored from one patch is found in another through NCC, at the other's phase and
// quarter turn, and renders that patch faithfully: the phase travels in the instance.
#include <cmath>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>

#include "pattern/pattern_test_support.h"
#include "tessera/match/match_cascade.h"
#include "tessera/match/pattern_alignment.h"
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

TEST(PatternReuse, TheLatticesAlignTwoPatchesTurnedAFewDegreesApart) {
  // Two walls of the same bricks, each texel grid aligned with its own patch: 2.5 degrees and
  // 0.4 % of scale apart, which quarter-turn cross-correlation cannot follow over 300 texels.
  const cv::Mat tile = testing::randomTile(24, 14, 5);
  const core::Lattice2 truth{{24.0, 0.0}, {12.0, 14.0}};
  const cv::Mat first = testing::tiling(tile, truth, 300, 220, {1.0, 0.0, 7.0, 2.0});
  const PatternAnalysis analysis = analysePattern(first, {});
  ASSERT_TRUE(analysis.pattern) << analysis.reason;
  const match::MatchConfig config;
  const auto stored =
      match::patternTexture(1, analysis.pattern->tile_rgb, analysis.pattern->tile_mask,
                            analysis.pattern->lattice, config);

  const core::Similarity2 second_to_frame =
      core::Similarity2::fromAngleScale(2.5 * M_PI / 180.0, 1.004, 31.0, -9.0);
  const cv::Mat second = testing::tiling(tile, truth, 300, 220, second_to_frame);
  const PatternAnalysis other = analysePattern(second, {});
  ASSERT_TRUE(other.pattern) << other.reason;
  const std::optional<core::Similarity2> aligned = match::alignPattern(
      other.pattern->tile_rgb, other.pattern->tile_mask, other.pattern->lattice, *stored);
  ASSERT_TRUE(aligned);
  const core::Similarity2 refined = match::refineAlignment(second, {}, *stored, *aligned);
  // The first bitmap is the stored frame: the truth is second_to_frame followed by the
  // first's frame -> texel map, whose turn is 0.
  EXPECT_NEAR(refined.angleRad() * 180.0 / M_PI, 2.5, 0.1);
  EXPECT_NEAR(refined.scale(), 1.004, 0.002);
  const match::Fidelity fidelity = match::measureFidelity(
      second, {}, match::renderStored(*stored, refined, second.cols, second.rows));
  EXPECT_GT(fidelity.psnr_db, 30.0);

  // Through quarter-turn NCC alone the same pair is not faithful.
  const match::CandidateVerdict ncc = match::MatchCascade(config).tryCandidate(
      match::describeTexture(second, {}, config), *stored, 0.0);
  EXPECT_FALSE(ncc.accepted) << ncc.psnr_db << " dB";
  EXPECT_LT(ncc.psnr_db, config.min_psnr_db);

  // Another lattice shape is not a similarity of this one.
  const auto square = match::patternTexture(2, testing::randomTile(20, 20, 6), {},
                                            {{20.0, 0.0}, {0.0, 20.0}}, config);
  EXPECT_FALSE(match::alignPattern(other.pattern->tile_rgb, other.pattern->tile_mask,
                                   other.pattern->lattice, *square));
}

// A floor's tiles can be a cell of hundreds of texels a side: the phase is searched on a
// coarser grid first, and still lands on the stored tile's phase.
TEST(PatternReuse, ALargeCellFindsItsPhaseThroughTheCoarseSearch) {
  const int w = 160, h = 120;  // 19,200 texels: more phases than the one-texel grid tries
  const cv::Mat tile = testing::randomTile(w, h, 9);
  const core::Lattice2 lattice{{static_cast<double>(w), 0.0}, {0.0, static_cast<double>(h)}};
  const match::MatchConfig config;
  const auto stored = match::patternTexture(1, tile, {}, lattice, config);
  // The same tile, starting 37 texels along and 51 down: another phase of the same floor.
  cv::Mat shifted(h, w, CV_8UC3);
  for (int j = 0; j < h; ++j) {
    for (int i = 0; i < w; ++i)
      shifted.at<cv::Vec3b>(j, i) = tile.at<cv::Vec3b>((j + 51) % h, (i + 37) % w);
  }
  const auto aligned = match::alignPattern(shifted, {}, lattice, *stored);
  ASSERT_TRUE(aligned);
  EXPECT_NEAR(aligned->scale(), 1.0, 1e-6);
  const double tx = std::fmod(aligned->tx + w, w), ty = std::fmod(aligned->ty + h, h);
  // Within a texel (the stored tile is sampled at texel corners, the new one at centres).
  EXPECT_NEAR(tx, 37.0, 1.0);
  EXPECT_NEAR(ty, 51.0, 1.0);
  const match::Fidelity fidelity =
      match::measureFidelity(shifted, {}, match::renderStored(*stored, *aligned, w, h));
  EXPECT_GT(fidelity.psnr_db, 30.0) << "phase " << tx << ", " << ty;
}

}  // namespace
}  // namespace tessera::pattern
