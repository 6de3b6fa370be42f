#include "tessera/pattern/pattern_extractor.h"
#include "tessera/pattern/overlays.h"

#include <cmath>
#include <filesystem>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "pattern/pattern_test_support.h"
#include "tessera/core/error.h"

namespace tessera::pattern {
namespace {

using testing::randomTile;
using testing::tiling;

constexpr double kPi = 3.14159265358979323846;

// The pattern found in `image`, asserting it is exact: the lattices generate each other
// within 1 texel (METRICS.md, period error).
void expectLattice(const cv::Mat& image, const cv::Mat& mask, const core::Lattice2& truth,
                   const std::string& what) {
  const PatternAnalysis analysis = analysePattern(image, mask);
  ASSERT_TRUE(analysis.pattern) << what << ": " << analysis.reason;
  const core::Lattice2& found = analysis.pattern->lattice;
  EXPECT_EQ(analysis.pattern->periodicity, Periodicity::kTwoDirections) << what;
  EXPECT_TRUE(sameLattice(found, truth, 1.0))
      << what << ": found (" << found.v1.transpose() << "), (" << found.v2.transpose()
      << "), truth (" << truth.v1.transpose() << "), (" << truth.v2.transpose() << ")";
}

TEST(Lattice, ReducedBasisIsShortestAndSame) {
  const core::Lattice2 skewed{{20.0, 0.0}, {67.0, 13.0}};  // = (7, 13) + 3 (20, 0)
  const core::Lattice2 reduced = reduceBasis(skewed);
  EXPECT_TRUE(sameLattice(reduced, skewed, 1e-9));
  EXPECT_LE(reduced.v1.norm(), reduced.v2.norm());
  EXPECT_LE(std::abs(reduced.v1.dot(reduced.v2)), 0.5 * reduced.v1.squaredNorm() + 1e-9);
  EXPECT_NEAR(reduced.v1.norm(), std::hypot(7.0, 13.0), 1e-9);
  EXPECT_FALSE(sameLattice(reduced, {{40.0, 0.0}, {7.0, 13.0}}, 1.0));  // index 2
}

TEST(PatternExtractor, FindsShearedAndTurnedLattices) {
  const cv::Mat tile = randomTile(24, 16, 3);
  const core::Lattice2 lattices[] = {
      {{24.0, 0.0}, {0.0, 16.0}},                     // rectangular
      {{24.0, 0.0}, {9.0, 16.0}},                     // sheared
      {{21.0 * std::cos(0.4), 21.0 * std::sin(0.4)},  // turned by 23 degrees,
       {-18.0 * std::sin(0.4) + 5.0 * std::cos(0.4), 18.0 * std::cos(0.4) + 5.0 * std::sin(0.4)}},
  };
  for (const core::Lattice2& truth : lattices) {
    expectLattice(tiling(tile, truth, 200, 160), {}, truth, "tiling");
  }
}

TEST(PatternExtractor, RunningBondBricksAreOneShearedLattice) {
  // Bricks 30 x 10 texels with 2-texel mortar, each course offset by half a brick.
  cv::Mat wall(180, 240, CV_8UC3, cv::Scalar(200, 200, 190));
  for (int course = 0; course * 12 < wall.rows; ++course) {
    const int offset = (course % 2) * 16;
    for (int x = -32 + offset; x < wall.cols; x += 32) {
      cv::rectangle(wall, cv::Rect(x, course * 12, 30, 10), cv::Scalar(150, 60, 40), cv::FILLED);
    }
  }
  expectLattice(wall, {}, {{32.0, 0.0}, {16.0, 12.0}}, "running bond");
}

TEST(PatternExtractor, StripesArePeriodicInOneDirection) {
  // Stripes 9 texels apart, turned by 20 degrees, unchanged along their length.
  const double angle = 20.0 * kPi / 180.0;
  const Eigen::Vector2d across(std::cos(angle), std::sin(angle));
  cv::Mat stripes(160, 200, CV_8UC3);
  for (int y = 0; y < stripes.rows; ++y) {
    for (int x = 0; x < stripes.cols; ++x) {
      const double t = across.dot(Eigen::Vector2d(x, y)) / 9.0;
      const double g = 128 + 90 * std::sin(2 * kPi * t) + 30 * std::sin(4 * kPi * t);
      stripes.at<cv::Vec3b>(y, x) = cv::Vec3b::all(cv::saturate_cast<uchar>(g));
    }
  }
  const PatternAnalysis analysis = analysePattern(stripes, {});
  ASSERT_TRUE(analysis.pattern) << analysis.reason;
  EXPECT_EQ(analysis.pattern->periodicity, Periodicity::kOneDirection);
  const Eigen::Vector2d along(-across.y(), across.x());
  // The stripes' symmetries: 9 texels across, anything along.
  const core::Lattice2 truth{9.0 * across, 37.0 * along};
  EXPECT_TRUE(sameStripes(analysis.pattern->lattice.v1, analysis.pattern->lattice.v2.normalized(),
                          truth, 1.0))
      << analysis.pattern->lattice.v1.transpose();
  EXPECT_NEAR(std::abs(analysis.pattern->lattice.v1.normalized().dot(across)), 1.0, 0.01);
}

TEST(PatternExtractor, ToleratesNoiseAndOcclusion) {
  const cv::Mat tile = randomTile(20, 26, 5);
  const core::Lattice2 truth{{20.0, 0.0}, {6.0, 26.0}};
  cv::Mat image = tiling(tile, truth, 240, 200);
  cv::Mat noisy;
  image.convertTo(noisy, CV_32FC3);
  cv::Mat noise(noisy.size(), CV_32FC3);
  cv::RNG(11).fill(noise, cv::RNG::NORMAL, 0.0, 8.0);
  noisy += noise;
  noisy.convertTo(noisy, CV_8UC3);
  expectLattice(noisy, {}, truth, "noise sigma 8");

  // 20 % hidden behind an unrelated object, which the tile's median outvotes.
  cv::Mat occluded = image.clone();
  const cv::Rect object(60, 50, 110, 87);
  randomTile(object.width, object.height, 99).copyTo(occluded(object));
  expectLattice(occluded, {}, truth, "20 % occluded");
  const PatternAnalysis analysis = analysePattern(occluded, {});
  ASSERT_TRUE(analysis.pattern);
  ASSERT_FALSE(analysis.pattern->overlays.empty());
  const cv::Rect overlay = analysis.pattern->overlays.front();
  EXPECT_GT((overlay & object).area(), 0.8 * object.area());  // the object is the overlay
  EXPECT_LT(overlay.area(), 1.3 * object.area());

  // And through a mask: a third of the bitmap has no texels.
  cv::Mat mask(image.size(), CV_8UC1, cv::Scalar(255));
  cv::fillConvexPoly(mask, std::vector<cv::Point>{{0, 0}, {160, 0}, {0, 200}}, cv::Scalar(0));
  expectLattice(image, mask, truth, "masked");
}

TEST(PatternExtractor, TheTileReproducesTheBitmapAtItsPhase) {
  // The bitmap starts at an arbitrary phase of the pattern: the tile is cut at the bitmap's
  // origin, so the tiling through the identity reproduces it.
  const cv::Mat tile = randomTile(18, 14, 8);
  const core::Lattice2 truth{{18.0, 0.0}, {0.0, 14.0}};
  const cv::Mat bitmap = tiling(tile, truth, 150, 120, {1.0, 0.0, 7.3, 4.6});
  const PatternAnalysis analysis = analysePattern(bitmap, {});
  ASSERT_TRUE(analysis.pattern) << analysis.reason;
  const Pattern& p = *analysis.pattern;
  const match::Rendered shown =
      match::renderPattern(p.tile_rgb, p.tile_mask, p.lattice, {}, bitmap.cols, bitmap.rows);
  const match::Fidelity fidelity = match::measureFidelity(bitmap, {}, shown);
  EXPECT_GT(fidelity.psnr_db, 35.0);
  EXPECT_EQ(fidelity.coverage, 1.0);
  EXPECT_EQ(p.tile_rgb.total(), 18u * 14u);  // one cell, whichever vector comes first
}

// A floor lit from one side (the light falls off by half across it) with a spotlight on it
// (+60 % at its centre, Gaussian): the shading is a smooth gain field over the tiling.
cv::Mat floorLight(cv::Size size) {
  cv::Mat gain(size, CV_32FC1);
  const cv::Point2f spot(0.62F * static_cast<float>(size.width),
                         0.4F * static_cast<float>(size.height));
  const float spot_sigma = 0.18F * static_cast<float>(size.width);
  for (int row = 0; row < size.height; ++row) {
    for (int col = 0; col < size.width; ++col) {
      const float falloff = 1.0F - 0.5F * static_cast<float>(col) / static_cast<float>(size.width);
      const float dx = static_cast<float>(col) - spot.x, dy = static_cast<float>(row) - spot.y;
      const float spotlight = 0.6F * std::exp(-(dx * dx + dy * dy) / (2 * spot_sigma * spot_sigma));
      gain.at<float>(row, col) = 0.75F * (falloff + spotlight);
    }
  }
  return gain;
}

cv::Mat lit(const cv::Mat& rgb, const cv::Mat& gain) {
  cv::Mat out(rgb.size(), CV_8UC3);
  for (int row = 0; row < rgb.rows; ++row) {
    for (int col = 0; col < rgb.cols; ++col) {
      for (int c = 0; c < 3; ++c) {
        out.at<cv::Vec3b>(row, col)[c] = cv::saturate_cast<std::uint8_t>(
            gain.at<float>(row, col) * static_cast<float>(rgb.at<cv::Vec3b>(row, col)[c]));
      }
    }
  }
  return out;
}

TEST(PatternExtractor, ATiledFloorUnderUnevenLightIsTileTimesShading) {
  // Tiles of 22 x 26 texels, darkened by half across the floor and lit by a spotlight: the
  // lattice is exact, the shading recovered within a few percent of the light (up to its mean,
  // which the tile carries), and tile x shading renders the floor at 30 dB or more.
  const cv::Mat tile = randomTile(22, 26, 21);
  const core::Lattice2 truth{{22.0, 0.0}, {4.0, 26.0}};
  const cv::Mat even = tiling(tile, truth, 320, 240);
  const cv::Mat light = floorLight(even.size());
  const cv::Mat floor = lit(even, light);
  const PatternAnalysis analysis = analysePattern(floor, {});
  ASSERT_TRUE(analysis.pattern) << analysis.reason;
  const Pattern& p = *analysis.pattern;
  EXPECT_TRUE(sameLattice(p.lattice, truth, 1.0))
      << "found (" << p.lattice.v1.transpose() << "), (" << p.lattice.v2.transpose() << ")";
  ASSERT_FALSE(p.shading.empty());
  EXPECT_GT(p.shading_spread, 0.3);

  // The light up to its mean: within 5 % on 95 % of the floor (measured: all of it, 1.3 % on
  // average), away from the border where
  // the window runs out.
  const cv::Mat relative = light / cv::mean(light)[0];
  const cv::Rect inner(24, 24, floor.cols - 48, floor.rows - 48);
  cv::Mat error;
  cv::absdiff(p.shading(inner), relative(inner), error);
  error /= relative(inner);
  EXPECT_GT(cv::countNonZero(error < 0.05), 0.95 * static_cast<double>(inner.area()));

  // What the map would show: the tile's tiling times the shading.
  const match::Rendered tiled =
      match::renderPattern(p.tile_rgb, p.tile_mask, p.lattice, {}, floor.cols, floor.rows);
  match::Rendered shown = tiled;
  shown.rgb = lit(tiled.rgb, p.shading);
  // Measured 37.2 dB; the tile without its shading reaches 23.2.
  const double with_shading = match::measureFidelity(floor, {}, shown).psnr_db;
  EXPECT_GE(with_shading, 30.0);
  EXPECT_LT(match::measureFidelity(floor, {}, tiled).psnr_db, with_shading - 8.0);
}

TEST(PatternExtractor, EvenLightHasNoShading) {
  const cv::Mat tile = randomTile(20, 20, 4);
  const PatternAnalysis analysis =
      analysePattern(tiling(tile, {{20.0, 0.0}, {0.0, 20.0}}, 200, 160), {});
  ASSERT_TRUE(analysis.pattern) << analysis.reason;
  EXPECT_TRUE(analysis.pattern->shading.empty());
}

TEST(PatternExtractor, StochasticTexturesAreNotPeriodic) {
  // Smooth random fields at several grain sizes: at most 5 % may be called periodic.
  int periodic = 0, total = 0;
  for (int seed = 0; seed < 8; ++seed) {
    for (const double grain : {1.0, 3.0, 8.0}) {
      cv::Mat field(192, 224, CV_32FC3);
      cv::RNG(static_cast<std::uint64_t>(100 + seed)).fill(field, cv::RNG::NORMAL, 128.0, 60.0);
      cv::GaussianBlur(field, field, cv::Size(), grain);
      cv::normalize(field, field, 0, 255, cv::NORM_MINMAX);
      field.convertTo(field, CV_8UC3);
      periodic += analysePattern(field, {}).pattern ? 1 : 0;
      ++total;
    }
  }
  EXPECT_LE(periodic, total / 20);
}

TEST(PatternExtractor, RealPhotographsOfGrassAndGravelAreNotPeriodic) {
  const std::filesystem::path dir =
      std::filesystem::path(TESSERA_SHARED_DATA_DIR) / "textures/skimage_cc0";
  if (!std::filesystem::exists(dir / "grass.png")) {
    GTEST_SKIP() << dir << " is absent: the shared test data is not beside this clone";
  }
  for (const char* name : {"grass.png", "gravel.png"}) {
    cv::Mat grey = cv::imread((dir / name).string(), cv::IMREAD_COLOR);
    ASSERT_FALSE(grey.empty()) << name;
    EXPECT_FALSE(analysePattern(grey, {}).pattern) << name;
  }
}

TEST(PatternExtractor, RefusesWhatItCannotRead) {
  EXPECT_THROW(analysePattern(cv::Mat(), {}), core::Error);
  EXPECT_THROW(analysePattern(cv::Mat(10, 10, CV_8UC1), {}), core::Error);
  EXPECT_THROW(analysePattern(cv::Mat(10, 10, CV_8UC3), cv::Mat(5, 5, CV_8UC1)), core::Error);
  // A plain surface has no period, and says so.
  const PatternAnalysis plain =
      analysePattern(cv::Mat(64, 64, CV_8UC3, cv::Scalar(90, 90, 90)), {});
  EXPECT_FALSE(plain.pattern);
  EXPECT_FALSE(plain.reason.empty());
}

// A poster pasted on a noisy render is one overlay whose box is the poster's, and the noise
// alone leaves nothing unexplained.
TEST(Overlays, APastedRectangleIsOneBlobWithItsBox) {
  const cv::Mat wall =
      testing::tiling(testing::randomTile(30, 20, 8), {{30.0, 0.0}, {15.0, 20.0}}, 300, 200);
  cv::Mat seen = wall.clone();
  cv::Mat noise(wall.size(), CV_16SC3);
  cv::RNG(3).fill(noise, cv::RNG::NORMAL, 0.0, 3.0);
  seen.convertTo(seen, CV_16SC3);
  seen += noise;
  seen.convertTo(seen, CV_8UC3);
  const cv::Mat all(wall.size(), CV_8UC1, cv::Scalar(255));
  EXPECT_TRUE(findOverlays(colourError(seen, wall), all, {}).blobs.empty());

  const cv::Rect poster(120, 40, 60, 90);
  cv::Mat poster_pixels = seen(poster);
  cv::randu(poster_pixels, cv::Scalar::all(0), cv::Scalar::all(255));
  cv::GaussianBlur(poster_pixels, poster_pixels, {9, 9}, 3.0);
  seen(cv::Rect(130, 50, 40, 70)).setTo(cv::Scalar(250, 250, 240));  // a plain middle
  const Overlays found = findOverlays(colourError(seen, wall), all, {});
  ASSERT_EQ(found.blobs.size(), 1u);
  EXPECT_LE(std::abs(found.blobs[0].x - poster.x), 4);
  EXPECT_LE(std::abs(found.blobs[0].y - poster.y), 4);
  EXPECT_LE(std::abs(found.blobs[0].br().x - poster.br().x), 4);
  EXPECT_LE(std::abs(found.blobs[0].br().y - poster.br().y), 4);
  const double share = static_cast<double>(poster.area()) / static_cast<double>(wall.total());
  EXPECT_NEAR(found.unexplained_share, share, 0.25 * share);
}

}  // namespace
}  // namespace tessera::pattern
