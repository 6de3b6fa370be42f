// The reuse decision against a catalog in memory, one test per branch of planCommit: a reuse,
// a refused reuse, a pattern base with overlays, a stored pattern reused through its lattice, a
// partial base with an overlay (planned serially, and from overlays prepared ahead), a plan
// that loses fidelity and falls back to the whole bitmap, pixels already stored, and matching
// switched off. Every image is seeded.
#include "tessera/reuse/commit_plan.h"

#include <map>
#include <random>

#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

#include "pattern/pattern_test_support.h"
#include "support/random_shapes.h"
#include "tessera/match/fidelity.h"
#include "tessera/pattern/pattern_extractor.h"
#include "tessera/reuse/layer_plan.h"

namespace tessera::reuse {
namespace {

cv::Mat shapes(int width, int height, unsigned seed) {
  return test::randomShapes(width, height, seed);
}

// A patch's bitmap with every texel observed.
texture::PatchBitmap bitmapOf(const cv::Mat& rgb, int patch_id) {
  texture::PatchBitmap bitmap;
  bitmap.id = patch_id;
  bitmap.version = 1;
  bitmap.grid.texel_m = 0.005;
  bitmap.grid.width = rgb.cols;
  bitmap.grid.height = rgb.rows;
  bitmap.grid.mask = cv::Mat(rgb.size(), CV_8UC1, cv::Scalar(255));
  bitmap.image = rgb;
  bitmap.state =
      cv::Mat(rgb.size(), CV_8UC1, cv::Scalar(static_cast<int>(texture::TexelState::kObserved)));
  bitmap.observed = rgb.total();
  return bitmap;
}

const cv::Mat kAll;  // an empty mask: every texel valid

class CommitPlanTest : public ::testing::Test {
 protected:
  void SetUp() override { cv::setRNGSeed(7); }

  // A single texture in the catalog, described as the commit stage describes one.
  void storeSingle(std::int64_t id, const cv::Mat& rgb) {
    auto texture = std::make_shared<match::StoredTexture>();
    texture->id = id;
    texture->description = match::describeTexture(rgb, kAll, rules_.match);
    catalog_.add(texture);
  }

  match::TextureDescription describe(const cv::Mat& rgb) const {
    return match::describeTexture(rgb, cv::Mat(rgb.size(), CV_8UC1, cv::Scalar(255)), rules_.match);
  }

  CommitPlan plan(const cv::Mat& rgb, const std::optional<pattern::Pattern>& found = {},
                  const PreparedLayers* prepared = nullptr) {
    const texture::PatchBitmap bitmap = bitmapOf(rgb, 42);
    const match::TextureDescription description = describe(rgb);
    const auto stored_pixels = [this](const std::string& key) -> std::optional<std::int64_t> {
      const auto it = stored_keys_.find(key);
      return it == stored_keys_.end() ? std::nullopt : std::optional<std::int64_t>(it->second);
    };
    CommitPlan plan =
        planCommit(bitmap, description, found, catalog_, stored_pixels, rules_, nullptr, prepared);
    // Whatever the branch: layer 0 first, layers numbered in order, one patch, one run.
    for (std::size_t i = 0; i < plan.commit.instances.size(); ++i) {
      const db::TextureInstance& instance = plan.commit.instances[i];
      EXPECT_EQ(instance.layer, static_cast<int>(i));
      EXPECT_EQ(instance.patch_id, 42);
      EXPECT_EQ(instance.run_id, rules_.run_id);
      EXPECT_NE(instance.texture_id, 0);
      // A new texture is named by its place in the commit; a reuse by a stored id.
      EXPECT_EQ(instance.reused, instance.texture_id > 0);
    }
    EXPECT_EQ(plan.fresh.size(), plan.commit.textures.size());
    for (const db::TextureRecord& texture : plan.commit.textures) {
      EXPECT_EQ(texture.run_id, rules_.run_id);
      EXPECT_EQ(texture.content_key, db::contentKey(texture.rgb, texture.mask));
    }
    return plan;
  }

  struct TurnedWall {
    cv::Mat tile;
    core::Lattice2 lattice;
    cv::Mat wall;
  };
  // A pattern stored as texture 7, and the same pattern on another wall, its texel grid a
  // quarter turn and a shift away.
  TurnedWall storePatternAndTurnItsWall() {
    TurnedWall turned{pattern::testing::randomTile(24, 18, 12), {{24.0, 0.0}, {0.0, 18.0}}, {}};
    catalog_.add(match::patternTexture(7, turned.tile, cv::Mat(), turned.lattice, rules_.match));
    const core::Similarity2 quarter = core::Similarity2::fromAngleScale(CV_PI / 2, 1.0, 5.0, 3.0);
    turned.wall = pattern::testing::tiling(turned.tile, turned.lattice, 200, 150, quarter);
    return turned;
  }

  CommitRules rules_{{}, {}, 5};
  match::MemoryCatalog catalog_{rules_.match.ccv};
  std::map<std::string, std::int64_t> stored_keys_;
};

// The bitmap the camera would give of `texture` seen through `patch_to_texture`.
cv::Mat seenThrough(const cv::Mat& texture, const core::Similarity2& patch_to_texture, int width,
                    int height) {
  const match::Rendered view =
      match::renderThrough(texture, kAll, patch_to_texture, width, height, false);
  EXPECT_EQ(cv::countNonZero(view.covered), width * height);
  return view.rgb;
}

TEST_F(CommitPlanTest, AStoredTextureThatShowsTheBitmapIsReusedWithItsTransform) {
  const cv::Mat wall = shapes(400, 300, 5);
  storeSingle(1, shapes(400, 300, 99));  // unrelated
  storeSingle(2, wall);
  const core::Similarity2 truth = core::Similarity2::fromAngleScale(0.5, 1.0, 200.0, 40.0);
  const CommitPlan plan = this->plan(seenThrough(wall, truth, 160, 120));
  ASSERT_EQ(plan.commit.instances.size(), 1u);
  EXPECT_TRUE(plan.commit.textures.empty());
  const db::TextureInstance& base = plan.base();
  EXPECT_EQ(base.texture_id, 2);
  ASSERT_TRUE(base.psnr_db);
  EXPECT_TRUE(rules_.match.accepts({*base.psnr_db, 1.0, 0}));
  for (const Eigen::Vector2d& p : {Eigen::Vector2d(0, 0), Eigen::Vector2d(159, 119)}) {
    EXPECT_LT((base.transform.apply(p) - truth.apply(p)).norm(), 1.0) << p.transpose();
  }
  EXPECT_TRUE(plan.method == "features" || plan.method == "ncc") << plan.method;
  EXPECT_EQ(plan.ccv_considered, 2u);
}

TEST_F(CommitPlanTest, AReuseShortOfTheRuleIsRefusedAndTheBitmapStoredWhole) {
  const cv::Mat wall = shapes(400, 300, 5);
  storeSingle(2, wall);
  // The same surface under far brighter light: placed by its features, but about 18 dB.
  cv::Mat brighter = seenThrough(wall, {1.0, 0.0, 100.0, 80.0}, 160, 120);
  brighter += cv::Scalar::all(32);
  const CommitPlan plan = this->plan(brighter);
  ASSERT_EQ(plan.commit.instances.size(), 1u);
  ASSERT_EQ(plan.commit.textures.size(), 1u);
  EXPECT_EQ(plan.method, "stored");
  EXPECT_EQ(plan.base().texture_id, -1);
  EXPECT_FALSE(plan.base().psnr_db);
  const db::TextureRecord& texture = plan.commit.textures.front();
  EXPECT_EQ(texture.kind, db::TextureKind::kSingle);
  EXPECT_EQ(cv::norm(texture.rgb, brighter, cv::NORM_INF), 0.0);
  EXPECT_EQ(texture.source_patch, 42);
  EXPECT_DOUBLE_EQ(texture.texel_m, 0.005);
  EXPECT_FALSE(plan.fresh.front()->description.ccv.values.empty());
}

TEST_F(CommitPlanTest, APatternWithAPosterIsOneTileAndTheCropAsAnOverlay) {
  const cv::Mat tile = pattern::testing::randomTile(20, 26, 5);
  const core::Lattice2 lattice{{20.0, 0.0}, {6.0, 26.0}};
  cv::Mat wall = pattern::testing::tiling(tile, lattice, 240, 200);
  const cv::Rect poster(60, 50, 60, 70);
  shapes(poster.width, poster.height, 31).copyTo(wall(poster));
  const pattern::PatternAnalysis analysis =
      pattern::analysePattern(wall, kAll, rules_.patterns.extractor);
  ASSERT_TRUE(analysis.pattern) << analysis.reason;

  const CommitPlan plan = this->plan(wall, analysis.pattern);
  EXPECT_EQ(plan.method, "pattern");
  ASSERT_EQ(plan.commit.instances.size(), 2u);
  ASSERT_EQ(plan.commit.textures.size(), 2u);
  const db::TextureRecord& stored_tile = plan.commit.textures[0];
  EXPECT_EQ(stored_tile.kind, db::TextureKind::kPattern);
  ASSERT_TRUE(stored_tile.lattice);
  EXPECT_NEAR(std::abs(stored_tile.lattice->v1.x() * stored_tile.lattice->v2.y() -
                       stored_tile.lattice->v1.y() * stored_tile.lattice->v2.x()),
              20.0 * 26.0, 1.0);  // one cell
  EXPECT_TRUE(plan.fresh[0]->pattern);
  EXPECT_EQ(plan.base().texture_id, -1);
  ASSERT_TRUE(plan.base().psnr_db);
  EXPECT_GE(*plan.base().psnr_db, rules_.match.min_psnr_db);

  // The overlay: the poster's box (with its margin), its own pixels, drawn 1:1.
  const db::TextureRecord& crop = plan.commit.textures[1];
  const db::TextureInstance& overlay = plan.commit.instances[1];
  EXPECT_EQ(crop.kind, db::TextureKind::kSingle);
  EXPECT_EQ(overlay.texture_id, -2);
  EXPECT_FALSE(overlay.psnr_db);
  const cv::Rect box(static_cast<int>(-overlay.transform.tx),
                     static_cast<int>(-overlay.transform.ty), crop.rgb.cols, crop.rgb.rows);
  EXPECT_GT((box & poster).area(), 0.9 * poster.area());
  EXPECT_LT(box.area(), 1.5 * poster.area());
  EXPECT_EQ(cv::norm(crop.rgb(poster - box.tl()), wall(poster), cv::NORM_INF), 0.0);
  EXPECT_EQ(cv::countNonZero(crop.mask), crop.mask.total());  // stored opaque
}

TEST_F(CommitPlanTest, AStoredPatternIsReusedThroughItsLatticeByAWallTurnedAgainstIt) {
  const TurnedWall turned = storePatternAndTurnItsWall();
  const cv::Mat &tile = turned.tile, &wall = turned.wall;
  const core::Lattice2& lattice = turned.lattice;
  const pattern::PatternAnalysis analysis =
      pattern::analysePattern(wall, kAll, rules_.patterns.extractor);
  ASSERT_TRUE(analysis.pattern) << analysis.reason;

  const CommitPlan plan = this->plan(wall, analysis.pattern);
  ASSERT_EQ(plan.commit.instances.size(), 1u);
  EXPECT_TRUE(plan.commit.textures.empty());
  EXPECT_EQ(plan.base().texture_id, 7);
  EXPECT_TRUE(plan.method == "ncc" || plan.method == "lattice") << plan.method;
  ASSERT_TRUE(plan.base().psnr_db);
  EXPECT_GE(*plan.base().psnr_db, rules_.match.min_psnr_db);
  const match::Fidelity shown = match::measureFidelity(
      wall, kAll,
      match::renderPattern(tile, {}, lattice, plan.base().transform, wall.cols, wall.rows));
  EXPECT_TRUE(rules_.match.accepts(shown)) << shown.psnr_db << " dB";
}

TEST_F(CommitPlanTest, StoredPatternVerdictsPreparedAheadAreTakenAsPrepared) {
  const cv::Mat wall = storePatternAndTurnItsWall().wall;
  const pattern::PatternAnalysis analysis =
      pattern::analysePattern(wall, kAll, rules_.patterns.extractor);
  ASSERT_TRUE(analysis.pattern) << analysis.reason;
  const match::MatchCascade cascade(rules_.match);
  PreparedLayers prepared = LayerPlanner(cascade, catalog_, rules_.patterns)
                                .prepare(describe(wall), analysis.pattern, {});
  ASSERT_EQ(prepared.stored_patterns.verdicts.size(), 1u);
  EXPECT_TRUE(prepared.stored_patterns.verdicts[0].second.accepted);

  // With the cascade's own match set aside, the stored tile comes through the lattices, with
  // or without the prepared verdict; a prepared refusal is taken as it is.
  rules_.match.ncc_min_score = 1.1;
  const CommitPlan serial = plan(wall, analysis.pattern);
  const CommitPlan ahead = plan(wall, analysis.pattern, &prepared);
  EXPECT_EQ(serial.method, "lattice");
  EXPECT_EQ(ahead.method, serial.method);
  EXPECT_EQ(ahead.base().texture_id, 7);
  EXPECT_EQ(ahead.base().transform.tx, serial.base().transform.tx);
  EXPECT_EQ(ahead.base().transform.ty, serial.base().transform.ty);
  prepared.stored_patterns.verdicts[0].second.accepted = false;
  EXPECT_EQ(plan(wall, analysis.pattern, &prepared).method, "pattern");
}

TEST_F(CommitPlanTest, AStoredTextureWithAPosterOnItIsThePartialBaseOfTheBitmap) {
  const cv::Mat plaster = shapes(400, 300, 5);
  storeSingle(3, plaster);
  const core::Similarity2 truth{1.0, 0.0, 120.0, 70.0};
  cv::Mat wall = seenThrough(plaster, truth, 200, 150);
  const cv::Rect poster(70, 40, 50, 60);
  cv::Mat poster_pixels = wall(poster);
  cv::randu(poster_pixels, cv::Scalar::all(0), cv::Scalar::all(255));
  cv::GaussianBlur(poster_pixels, poster_pixels, {9, 9}, 3.0);

  const CommitPlan plan = this->plan(wall);
  EXPECT_EQ(plan.method.rfind("+overlays"), plan.method.size() - 9) << plan.method;
  ASSERT_EQ(plan.commit.instances.size(), 2u);
  ASSERT_EQ(plan.commit.textures.size(), 1u);  // the poster's crop only
  EXPECT_EQ(plan.base().texture_id, 3);
  for (const Eigen::Vector2d& p : {Eigen::Vector2d(0, 0), Eigen::Vector2d(199, 149)}) {
    EXPECT_LT((plan.base().transform.apply(p) - truth.apply(p)).norm(), 1.0) << p.transpose();
  }
  ASSERT_TRUE(plan.base().psnr_db);
  EXPECT_GE(*plan.base().psnr_db, rules_.match.min_psnr_db);  // all layers together
  const db::TextureRecord& crop = plan.commit.textures.front();
  const cv::Rect box(static_cast<int>(-plan.commit.instances[1].transform.tx),
                     static_cast<int>(-plan.commit.instances[1].transform.ty), crop.rgb.cols,
                     crop.rgb.rows);
  EXPECT_GT((box & poster).area(), 0.9 * poster.area());
  EXPECT_LT(box.area(), 2.0 * poster.area());
}

TEST_F(CommitPlanTest, OverlaysPreparedAheadGiveTheSamePlanAndAreTakenAsPrepared) {
  const cv::Mat plaster = shapes(400, 300, 5);
  storeSingle(3, plaster);
  cv::Mat wall = seenThrough(plaster, {1.0, 0.0, 120.0, 70.0}, 200, 150);
  cv::Mat poster = wall(cv::Rect(70, 40, 50, 60));
  cv::randu(poster, cv::Scalar::all(0), cv::Scalar::all(255));
  cv::GaussianBlur(poster, poster, {9, 9}, 3.0);
  // As the describing threads do it: the cascade ahead, then the overlays its verdicts imply.
  const match::TextureDescription description = describe(wall);
  const match::MatchCascade cascade(rules_.match);
  const match::PrecheckedVerdicts prechecked = cascade.precheck(description, catalog_);
  std::vector<match::CandidateVerdict> verdicts;
  for (const auto& entry : prechecked.verdicts) verdicts.push_back(entry.second);
  PreparedLayers prepared =
      LayerPlanner(cascade, catalog_, rules_.patterns).prepare(description, {}, verdicts);
  ASSERT_EQ(prepared.overlays.size(), 1u);

  const CommitPlan serial = plan(wall);
  const CommitPlan ahead = plan(wall, {}, &prepared);
  EXPECT_EQ(ahead.method, serial.method);
  ASSERT_EQ(ahead.commit.instances.size(), 2u);
  ASSERT_EQ(ahead.commit.instances.size(), serial.commit.instances.size());
  for (std::size_t i = 0; i < ahead.commit.instances.size(); ++i) {
    const db::TextureInstance &a = ahead.commit.instances[i], &b = serial.commit.instances[i];
    EXPECT_EQ(a.texture_id, b.texture_id);
    EXPECT_EQ(a.psnr_db, b.psnr_db);
    EXPECT_EQ(a.transform.tx, b.transform.tx);
    EXPECT_EQ(a.transform.ty, b.transform.ty);
  }
  ASSERT_EQ(ahead.commit.textures.size(), 1u);
  EXPECT_EQ(ahead.commit.textures[0].content_key, serial.commit.textures[0].content_key);

  // The crop stored is the one prepared, not worked out again.
  PreparedOverlay& crop = prepared.overlays[0];
  crop.opaque_rgb = cv::Mat(crop.opaque_rgb.size(), CV_8UC3, cv::Scalar(1, 2, 3));
  const CommitPlan marked = plan(wall, {}, &prepared);
  ASSERT_EQ(marked.commit.textures.size(), 1u);
  EXPECT_EQ(marked.commit.textures[0].rgb.at<cv::Vec3b>(0, 0), cv::Vec3b(1, 2, 3));
}

TEST_F(CommitPlanTest, LayersShortOfTheRuleFallBackToTheWholeBitmap) {
  // A noisy tiling: its pattern is found (the extractor's own bar is 20 dB), but under a rule
  // of 45 dB the tile cannot show the noise, and the bitmap is stored as it is.
  const cv::Mat tile = pattern::testing::randomTile(20, 26, 5);
  cv::Mat wall = pattern::testing::tiling(tile, {{20.0, 0.0}, {6.0, 26.0}}, 240, 200);
  cv::Mat noise(wall.size(), CV_16SC3);
  cv::RNG(11).fill(noise, cv::RNG::NORMAL, 0.0, 6.0);
  wall.convertTo(wall, CV_16SC3);
  wall += noise;
  wall.convertTo(wall, CV_8UC3);
  const pattern::PatternAnalysis analysis =
      pattern::analysePattern(wall, kAll, rules_.patterns.extractor);
  ASSERT_TRUE(analysis.pattern) << analysis.reason;

  rules_.match.min_psnr_db = 45.0;
  const CommitPlan plan = this->plan(wall, analysis.pattern);
  EXPECT_EQ(plan.method, "stored");
  ASSERT_EQ(plan.commit.instances.size(), 1u);
  ASSERT_EQ(plan.commit.textures.size(), 1u);
  EXPECT_EQ(plan.commit.textures.front().kind, db::TextureKind::kSingle);
  EXPECT_EQ(plan.commit.textures.front().rgb.size(), wall.size());

  // The same layers under the default rule are kept.
  rules_.match.min_psnr_db = match::MatchConfig{}.min_psnr_db;
  EXPECT_EQ(this->plan(wall, analysis.pattern).method, "pattern");
}

TEST_F(CommitPlanTest, PixelsAlreadyStoredAreNamedNotStoredAgain) {
  const cv::Mat wall = shapes(160, 120, 8);
  const cv::Mat all(wall.size(), CV_8UC1, cv::Scalar(255));
  stored_keys_[db::contentKey(wall, all)] = 11;
  const CommitPlan plan = this->plan(wall);
  EXPECT_TRUE(plan.commit.textures.empty());
  ASSERT_EQ(plan.commit.instances.size(), 1u);
  EXPECT_EQ(plan.base().texture_id, 11);
  EXPECT_EQ(plan.method, "same pixels");
  ASSERT_TRUE(plan.base().psnr_db);
  EXPECT_EQ(*plan.base().psnr_db, match::kIdenticalPsnrDb);
}

TEST_F(CommitPlanTest, WithMatchingOffEveryBitmapIsStoredAsItIs) {
  const cv::Mat wall = shapes(400, 300, 5);
  storeSingle(2, wall);
  rules_.match.enabled = false;
  const CommitPlan plan = this->plan(wall(cv::Rect(100, 80, 160, 120)).clone());
  EXPECT_EQ(plan.method, "stored");
  EXPECT_EQ(plan.ccv_considered, 0u);
  ASSERT_EQ(plan.commit.textures.size(), 1u);
  EXPECT_EQ(plan.base().texture_id, -1);
}

TEST(MatchConfig, AcceptsAtTheThresholdsAndSaysWhyNotBelowThem) {
  const match::MatchConfig config;
  EXPECT_TRUE(config.accepts({config.min_psnr_db, config.min_coverage, 100}));
  EXPECT_EQ(config.refusal({config.min_psnr_db - 0.1, 1.0, 100}), "PSNR 27.9 dB < 28.0");
  EXPECT_EQ(config.refusal({40.0, 0.5, 100}), "covers 50 % of the patch");
  EXPECT_FALSE(config.accepts({40.0, config.min_coverage - 0.01, 100}));
}

}  // namespace
}  // namespace tessera::reuse
