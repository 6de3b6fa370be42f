// The cascade end to end: a turned crop of a stored texture is found through features with the
// right transform, a turned and shifted repetition of a stored pattern tile through
// cross-correlation, and an unrelated texture is refused (by the CCV prefilter or the checks).
#include "tessera/match/match_cascade.h"

#include <cmath>
#include <numbers>
#include <random>

#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

#include "support/random_shapes.h"
#include "tessera/match/fidelity.h"

namespace tessera::match {
namespace {

cv::Mat texture(int width, int height, unsigned seed) {
  return test::randomShapes(width, height, seed);
}

std::shared_ptr<StoredTexture> stored(std::int64_t id, const cv::Mat& rgb, bool pattern,
                                      const MatchConfig& config) {
  if (pattern) {  // the image is one period each way
    return patternTexture(id, rgb, cv::Mat(), {{rgb.cols, 0.0}, {0.0, rgb.rows}}, config);
  }
  auto s = std::make_shared<StoredTexture>();
  s->id = id;
  s->description = describeTexture(rgb, cv::Mat(), config);
  return s;
}

// The farthest a corner of a width x height grid lands between two transforms, in texels.
double cornerError(const core::Similarity2& a, const core::Similarity2& b, int width, int height) {
  double worst = 0.0;
  for (const Eigen::Vector2d& corner :
       {Eigen::Vector2d(0, 0), Eigen::Vector2d(width, 0), Eigen::Vector2d(0, height),
        Eigen::Vector2d(width, height)}) {
    worst = std::max(worst, (a.apply(corner) - b.apply(corner)).norm());
  }
  return worst;
}

// An estimate a texel off (as features or correlation give) is brought to within a tenth of a
// texel by the direct alignment, and the render's fidelity rises with it.
TEST(MatchCascade, DirectAlignmentRefinesAnEstimateATexelOff) {
  cv::setRNGSeed(4);
  const MatchConfig config;
  cv::Mat big = texture(400, 300, 7);
  cv::GaussianBlur(big, big, cv::Size(), 1.5);  // detail at the scale of a real bitmap's
  const auto wall = stored(1, big, false, config);
  const core::Similarity2 truth =
      core::Similarity2::fromAngleScale(12.0 * std::numbers::pi / 180.0, 1.02, 150.0, 60.0);
  const Rendered query = renderThrough(big, cv::Mat(), truth, 180, 140, false);
  const TextureDescription described = describeTexture(query.rgb, query.covered, config);
  const core::Similarity2 estimate =
      core::Similarity2::fromAngleScale(12.4 * std::numbers::pi / 180.0, 1.02, 150.7, 59.4);
  ASSERT_GT(cornerError(estimate, truth, 180, 140), 0.9);

  const std::optional<core::Similarity2> refined = refinedByEcc(described, *wall, estimate);
  ASSERT_TRUE(refined.has_value());
  EXPECT_LT(cornerError(*refined, truth, 180, 140), 0.1);
  const auto psnr = [&](const core::Similarity2& transform) {
    return measureFidelity(query.rgb, query.covered, renderStored(*wall, transform, 180, 140))
        .psnr_db;
  };
  EXPECT_GT(psnr(*refined), psnr(estimate) + 5.0);
}

TEST(MatchCascade, ATurnedCropOfAStoredTextureReusesItWithTheRightTransform) {
  cv::setRNGSeed(3);
  const MatchConfig config;
  const cv::Mat big = texture(400, 300, 5);
  MemoryCatalog catalog(config.ccv);
  catalog.add(stored(1, texture(400, 300, 99), false, config));  // unrelated
  catalog.add(stored(2, big, false, config));
  // The new bitmap: texel (c, r) shows the stored texture at S(c, r), turned 30 degrees.
  const core::Similarity2 truth =
      core::Similarity2::fromAngleScale(30.0 * std::numbers::pi / 180.0, 1.0, 200.0, 40.0);
  const Rendered query = renderThrough(big, cv::Mat(), truth, 160, 120, false);
  ASSERT_EQ(cv::countNonZero(query.covered), 160 * 120);
  const MatchDecision decision =
      MatchCascade(config).match(describeTexture(query.rgb, query.covered, config), catalog);
  for (const CandidateVerdict& v : decision.verdicts) {
    SCOPED_TRACE(::testing::Message() << "candidate " << v.id << " CCV " << v.ccv_distance << ": "
                                      << v.method << " " << v.reason);
  }
  ASSERT_TRUE(decision.match.has_value())
      << ccvDistance(describeTexture(query.rgb, query.covered, config).ccv.values,
                     catalog.load(2)->description.ccv.values)
      << " " << decision.passed_ccv << " passed the prefilter; first: "
      << (decision.verdicts.empty() ? std::string("none") : decision.verdicts[0].reason);
  EXPECT_EQ(decision.match->id, 2);
  EXPECT_EQ(decision.match->method, "features");
  EXPECT_GE(decision.match->psnr_db, config.min_psnr_db);
  const core::Similarity2& found = *decision.match->transform;
  for (const Eigen::Vector2d& p : {Eigen::Vector2d(0, 0), Eigen::Vector2d(159, 119)}) {
    EXPECT_LT((found.apply(p) - truth.apply(p)).norm(), 1.0) << p.transpose();
  }
  EXPECT_EQ(decision.considered, 2u);
}

// Verdicts worked out ahead (on a describing thread) decide as verifying at the commit would,
// and are taken only for the very textures they were reached against.
TEST(MatchCascade, PrecheckedVerdictsDecideAsVerifyingAgainAndOnlyForTheSameTextures) {
  cv::setRNGSeed(3);
  const MatchConfig config;
  const cv::Mat big = texture(400, 300, 5);
  MemoryCatalog catalog(config.ccv);
  catalog.add(stored(1, texture(400, 300, 99), false, config));
  catalog.add(stored(2, big, false, config));
  const Rendered crop = renderThrough(
      big, cv::Mat(), core::Similarity2::fromAngleScale(0.5, 1.0, 200.0, 40.0), 160, 120, false);
  const TextureDescription query = describeTexture(crop.rgb, crop.covered, config);
  const MatchCascade cascade(config);
  const MatchDecision fresh = cascade.match(query, catalog);
  ASSERT_TRUE(fresh.match.has_value());
  PrecheckedVerdicts ahead = cascade.precheck(query, catalog);
  ASSERT_EQ(ahead.verdicts.size(), fresh.verdicts.size());
  const MatchDecision taken = cascade.match(query, catalog, &ahead);
  ASSERT_TRUE(taken.match.has_value());
  EXPECT_EQ(taken.match->id, fresh.match->id);
  EXPECT_EQ(taken.match->psnr_db, fresh.match->psnr_db);
  EXPECT_EQ(taken.match->transform->tx, fresh.match->transform->tx);
  EXPECT_EQ(taken.verdicts.size(), fresh.verdicts.size());

  // A verdict is taken, not worked out again: a refusal planted in it refuses.
  for (auto& [texture, verdict] : ahead.verdicts) {
    verdict.accepted = false;
    verdict.reason = "planted";
  }
  const MatchDecision planted = cascade.match(query, catalog, &ahead);
  EXPECT_FALSE(planted.match.has_value());
  ASSERT_FALSE(planted.verdicts.empty());
  EXPECT_EQ(planted.verdicts.front().reason, "planted");
  // The same ids, other objects (a texture removed and another stored under its id): verified.
  MemoryCatalog again(config.ccv);
  again.add(stored(1, texture(400, 300, 99), false, config));
  again.add(stored(2, big, false, config));
  const MatchDecision verified = cascade.match(query, again, &ahead);
  ASSERT_TRUE(verified.match.has_value());
  EXPECT_EQ(verified.match->psnr_db, fresh.match->psnr_db);
}

TEST(MatchCascade, ATurnedAndShiftedRepetitionOfAPatternTileIsFoundByCrossCorrelation) {
  const MatchConfig config;
  const cv::Mat tile = texture(48, 32, 7);
  MemoryCatalog catalog(config.ccv);
  catalog.add(stored(4, tile, true, config));
  // A wall of that tile, a quarter turn and a phase (11, 5) away from the tile's origin.
  const core::Similarity2 truth = core::Similarity2{0.0, 1.0, 11.0, 5.0};
  const Rendered wall = renderThrough(tile, cv::Mat(), truth, 200, 150, true);
  const MatchCascade matcher(config);
  const CandidateVerdict verdict =
      matcher.tryCandidate(describeTexture(wall.rgb, wall.covered, config), *catalog.load(4), 0.0);
  ASSERT_TRUE(verdict.accepted) << verdict.reason;
  EXPECT_EQ(verdict.method, "ncc");
  EXPECT_GE(verdict.psnr_db, 40.0);
  // The same tile texel up to whole periods.
  const Eigen::Vector2d p(37, 91);
  const Eigen::Vector2d a = verdict.transform->apply(p), b = truth.apply(p);
  EXPECT_NEAR(std::remainder(a.x() - b.x(), 48.0), 0.0, 0.5);
  EXPECT_NEAR(std::remainder(a.y() - b.y(), 32.0), 0.0, 0.5);
}

TEST(MatchCascade, ACropOfAStoredTextureAtAnyQuarterTurnIsPlacedInsideItByCrossCorrelation) {
  // A plain, fine-grained surface (features unable to help) seen again in part: the new bitmap
  // lies inside the stored one, turned by 0 to 3 quarter turns.
  MatchConfig config;
  config.features.min_inliers = 1'000'000;
  const cv::Mat big = texture(400, 300, 29);
  MemoryCatalog catalog(config.ccv);
  catalog.add(stored(8, big, false, config));
  const MatchCascade matcher(config);
  // New texel (c, r) -> stored texel, for a 160 x 120 crop inside the stored 400 x 300.
  for (const core::Similarity2& truth :
       {core::Similarity2{1.0, 0.0, 57.0, 31.0}, core::Similarity2{0.0, 1.0, 330.0, 40.0},
        core::Similarity2{-1.0, 0.0, 380.0, 250.0}, core::Similarity2{0.0, -1.0, 90.0, 270.0}}) {
    SCOPED_TRACE(::testing::Message() << "a " << truth.a << " b " << truth.b);
    const Rendered query = renderThrough(big, cv::Mat(), truth, 160, 120, false);
    ASSERT_EQ(cv::countNonZero(query.covered), 160 * 120);
    const CandidateVerdict verdict = matcher.tryCandidate(
        describeTexture(query.rgb, query.covered, config), *catalog.load(8), 0.0);
    ASSERT_TRUE(verdict.accepted) << verdict.reason;
    EXPECT_EQ(verdict.method, "ncc");
    for (const Eigen::Vector2d& p : {Eigen::Vector2d(0, 0), Eigen::Vector2d(159, 119)}) {
      EXPECT_LT((verdict.transform->apply(p) - truth.apply(p)).norm(), 0.5) << p.transpose();
    }
  }
}

TEST(MatchCascade, ATextureOverlappingAStoredOneInPartIsPlacedOverTheirCommonTexels) {
  // The same floor from two places: the new bitmap shows the stored texture's bottom-right
  // corner and more, a quarter turn away, neither inside the other. With features unable to
  // help (a plain, fine-grained surface), the masked cross-correlation places it exactly; the
  // acceptance rule then refuses it for covering under half of the patch.
  MatchConfig config;
  config.features.min_inliers = 1'000'000;
  const cv::Mat big = texture(600, 520, 23);
  MemoryCatalog catalog(config.ccv);
  catalog.add(stored(7, big(cv::Rect(0, 0, 400, 300)).clone(), false, config));
  // New texel (c, r) shows stored texel (330 - r, 170 + c): 320 x 320 texels, of which the
  // 130 columns c < 130 land inside the stored 400 x 300.
  const core::Similarity2 truth{0.0, 1.0, 330.0, 170.0};
  const Rendered query = renderThrough(big, cv::Mat(), truth, 320, 320, false);
  ASSERT_EQ(cv::countNonZero(query.covered), 320 * 320);
  const CandidateVerdict verdict = MatchCascade(config).tryCandidate(
      describeTexture(query.rgb, query.covered, config), *catalog.load(7), 0.0);
  EXPECT_EQ(verdict.method, "ncc");
  ASSERT_TRUE(verdict.transform.has_value()) << verdict.reason;
  for (const Eigen::Vector2d& p : {Eigen::Vector2d(0, 0), Eigen::Vector2d(319, 319)}) {
    EXPECT_LT((verdict.transform->apply(p) - truth.apply(p)).norm(), 0.5) << p.transpose();
  }
  EXPECT_NEAR(verdict.coverage, 130.0 / 320.0, 0.02);
  EXPECT_FALSE(verdict.accepted);
  EXPECT_GT(verdict.psnr_db, 35.0);  // over the texels both cover
}

// A layer plan's base is looked up by its CCV alone: describeColours must give describeTexture's
// CCV, at full size and scaled down, without the features' cost.
TEST(MatchCascade, ColoursAloneGiveTheFullDescriptionsCcv) {
  const MatchConfig config;
  for (const cv::Size size : {cv::Size(300, 200), cv::Size(900, 500)}) {
    const cv::Mat rgb = texture(size.width, size.height, 31);
    cv::Mat mask(rgb.size(), CV_8UC1, cv::Scalar(255));
    mask(cv::Rect(20, 30, 80, 60)).setTo(0);
    const TextureDescription full = describeTexture(rgb, mask, config);
    const TextureDescription colours = describeColours(rgb, mask, config);
    ASSERT_FALSE(full.features.keypoints.empty()) << size;
    EXPECT_TRUE(colours.features.keypoints.empty()) << size;
    EXPECT_EQ(colours.ccv.values, full.ccv.values) << size;
    EXPECT_EQ(colours.ccv.pixels, full.ccv.pixels) << size;
    EXPECT_EQ(cv::countNonZero(colours.mask != mask), 0) << size;
  }
}

TEST(MatchCascade, AnUnrelatedTextureIsStoredOnItsOwn) {
  const MatchConfig config;
  MemoryCatalog catalog(config.ccv);
  catalog.add(stored(1, texture(300, 200, 21), false, config));
  catalog.add(stored(2, texture(300, 200, 22), false, config));
  const cv::Mat other = texture(200, 150, 23);
  const MatchDecision decision =
      MatchCascade(config).match(describeTexture(other, cv::Mat(), config), catalog);
  EXPECT_FALSE(decision.match.has_value());
  EXPECT_EQ(decision.considered, 2u);
  for (const CandidateVerdict& verdict : decision.verdicts) EXPECT_FALSE(verdict.reason.empty());
}

TEST(MatchCascade, AFlatSurfaceDoesNotReuseAnotherFlatSurfaceOfTheSameColour) {
  // Same mean colour, no shared structure: PSNR alone would accept it; the structure check not.
  const MatchConfig config;
  cv::Mat a(120, 160, CV_8UC3, cv::Scalar(180, 170, 160)), b = a.clone();
  cv::Mat noise_a(a.size(), CV_8UC3), noise_b(a.size(), CV_8UC3);
  cv::randu(noise_a, cv::Scalar::all(0), cv::Scalar::all(6));
  cv::randu(noise_b, cv::Scalar::all(0), cv::Scalar::all(6));
  a += noise_a;
  b += noise_b;
  MemoryCatalog catalog(config.ccv);
  catalog.add(stored(1, b, false, config));
  const MatchDecision decision =
      MatchCascade(config).match(describeTexture(a, cv::Mat(), config), catalog);
  EXPECT_FALSE(decision.match.has_value());
}

}  // namespace
}  // namespace tessera::match
