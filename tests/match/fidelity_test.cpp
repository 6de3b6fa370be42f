// Rendering a texture through a similarity onto a texel grid, and the PSNR and coverage of a
// reuse: exact where the transform is exact, low where it is wrong.
#include "tessera/match/fidelity.h"

#include <cmath>
#include <numbers>
#include <random>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>

#include "tessera/core/error.h"

namespace tessera::match {
namespace {

cv::Mat randomRgb(int width, int height, unsigned seed) {
  std::mt19937 random(seed);
  std::uniform_int_distribution<int> level(0, 255);
  cv::Mat image(height, width, CV_8UC3);
  for (auto it = image.begin<cv::Vec3b>(); it != image.end<cv::Vec3b>(); ++it) {
    for (int c = 0; c < 3; ++c) (*it)[c] = static_cast<std::uint8_t>(level(random));
  }
  return image;
}

bool samePixels(const cv::Mat& a, const cv::Mat& b) {
  return a.size() == b.size() && a.type() == b.type() && cv::norm(a, b, cv::NORM_INF) == 0.0;
}

TEST(Fidelity, TheIdentityReproducesTheTexture) {
  const cv::Mat texture = randomRgb(50, 40, 41);
  const Rendered rendered = renderThrough(texture, {}, {}, 50, 40, false);
  EXPECT_TRUE(samePixels(rendered.rgb, texture));
  EXPECT_EQ(cv::countNonZero(rendered.covered), 50 * 40);
  const Fidelity fidelity = measureFidelity(texture, {}, texture, {}, {}, false);
  EXPECT_DOUBLE_EQ(fidelity.psnr_db, 99.0);
  EXPECT_DOUBLE_EQ(fidelity.coverage, 1.0);
  EXPECT_EQ(fidelity.texels, 50u * 40u);
}

TEST(Fidelity, ARotationByNinetyDegreesIsRenderedBackExactly) {
  const cv::Mat texture = randomRgb(30, 20, 42);
  cv::Mat patch;
  cv::rotate(texture, patch,
             cv::ROTATE_90_CLOCKWISE);  // patch (col, row) = texture (row, 19 - col)
  const auto patch_to_texture =
      core::Similarity2::fromAngleScale(-std::numbers::pi / 2, 1.0, 0.0, 19.0);
  const Rendered rendered =
      renderThrough(texture, {}, patch_to_texture, patch.cols, patch.rows, false);
  EXPECT_TRUE(samePixels(rendered.rgb, patch));
  EXPECT_EQ(cv::countNonZero(rendered.covered), patch.cols * patch.rows);
  EXPECT_DOUBLE_EQ(measureFidelity(patch, {}, texture, {}, patch_to_texture, false).psnr_db, 99.0);
}

TEST(Fidelity, ATiledRenderOfATileReproducesTheTiledImage) {
  const cv::Mat tile = randomRgb(16, 12, 43);
  cv::Mat tiled;
  cv::repeat(tile, 8, 9, tiled);
  // The patch starts 3 columns and 5 rows into the tiling, also when that offset lies many
  // periods away, or behind the origin.
  const cv::Mat patch = tiled(cv::Rect(3, 5, 100, 70)).clone();
  for (const double periods : {0.0, 1000.0, -7.0}) {
    const core::Similarity2 shift{1.0, 0.0, 3.0 + 16.0 * periods, 5.0 + 12.0 * periods};
    const Rendered rendered = renderThrough(tile, {}, shift, 100, 70, true);
    EXPECT_TRUE(samePixels(rendered.rgb, patch)) << periods;
    EXPECT_EQ(cv::countNonZero(rendered.covered), 100 * 70);
    const Fidelity fidelity = measureFidelity(patch, {}, tile, {}, shift, true);
    EXPECT_DOUBLE_EQ(fidelity.psnr_db, 99.0);
    EXPECT_DOUBLE_EQ(fidelity.coverage, 1.0);
  }
  // Not tiled, the tile covers only its own 16 x 12 texels of the grid.
  const core::Similarity2 origin{1.0, 0.0, 0.0, 0.0};
  EXPECT_EQ(cv::countNonZero(renderThrough(tile, {}, origin, 100, 70, false).covered), 16 * 12);
}

TEST(Fidelity, AWrongTransformGivesALowPsnr) {
  const cv::Mat texture = randomRgb(60, 60, 44);
  const cv::Mat patch = texture(cv::Rect(0, 0, 40, 40)).clone();
  const core::Similarity2 shifted{1.0, 0.0, 7.0, 2.0};
  const Fidelity wrong = measureFidelity(patch, {}, texture, {}, shifted, false);
  EXPECT_LT(wrong.psnr_db, 15.0);  // unrelated uniform noise: about 7.7 dB
  EXPECT_DOUBLE_EQ(wrong.coverage, 1.0);
  const Fidelity right = measureFidelity(patch, {}, texture, {}, {}, false);
  EXPECT_DOUBLE_EQ(right.psnr_db, 99.0);
}

TEST(Fidelity, CoverageCountsOnlyMaskTexelsThatLandOnTheTexture) {
  const cv::Mat texture = randomRgb(40, 40, 45);
  cv::Mat patch(40, 40, CV_8UC3, cv::Scalar::all(0));
  texture(cv::Rect(20, 0, 20, 40)).copyTo(patch(cv::Rect(0, 0, 20, 40)));
  // Columns 0-19 land on texture columns 20-39; columns 20-39 beyond its right edge.
  const core::Similarity2 shift{1.0, 0.0, 20.0, 0.0};
  const Fidelity half = measureFidelity(patch, {}, texture, {}, shift, false);
  EXPECT_DOUBLE_EQ(half.coverage, 0.5);
  EXPECT_EQ(half.texels, 20u * 40u);
  EXPECT_DOUBLE_EQ(half.psnr_db, 99.0);

  // A patch mask of the right half only: none of it is covered.
  cv::Mat right_half(40, 40, CV_8UC1, cv::Scalar(0));
  right_half(cv::Rect(20, 0, 20, 40)).setTo(255);
  const Fidelity none = measureFidelity(patch, right_half, texture, {}, shift, false);
  EXPECT_EQ(none.coverage, 0.0);
  EXPECT_EQ(none.psnr_db, 0.0);
  EXPECT_EQ(none.texels, 0u);

  // Masked-out texture texels cover nothing either: the top 10 rows.
  cv::Mat texture_mask(40, 40, CV_8UC1, cv::Scalar(255));
  texture_mask(cv::Rect(0, 0, 40, 10)).setTo(0);
  const Fidelity masked = measureFidelity(patch, {}, texture, texture_mask, shift, false);
  EXPECT_DOUBLE_EQ(masked.coverage, 20.0 * 30.0 / (40.0 * 40.0));
  EXPECT_DOUBLE_EQ(masked.psnr_db, 99.0);
}

TEST(Fidelity, MaskedOutTexelsDoNotBleedIntoTheirNeighbours) {
  // Valid texels one colour, masked-out ones black; sampled half a texel off, every covered
  // texel must still show the valid colour (bilinear over valid neighbours only).
  cv::Mat texture(20, 20, CV_8UC3, cv::Scalar(100, 150, 200));
  cv::Mat mask(20, 20, CV_8UC1, cv::Scalar(255));
  texture(cv::Rect(10, 0, 10, 20)).setTo(cv::Scalar::all(0));
  mask(cv::Rect(10, 0, 10, 20)).setTo(0);
  const core::Similarity2 half_texel{1.0, 0.0, 0.4, 0.3};
  const Rendered rendered = renderThrough(texture, mask, half_texel, 20, 20, false);
  ASSERT_EQ(cv::countNonZero(rendered.covered), 10 * 20);  // x + 0.4 rounds to a valid texel
  for (int r = 0; r < 20; ++r) {
    for (int c = 0; c < 20; ++c) {
      if (rendered.covered.at<std::uint8_t>(r, c) == 0) continue;
      const cv::Vec3b v = rendered.rgb.at<cv::Vec3b>(r, c);
      EXPECT_EQ(v, cv::Vec3b(100, 150, 200)) << c << "," << r;
    }
  }
}

// A small grid placed inside a large masked texture reads only the window of texels its samples
// touch; the colours are still the bilinear mean over the valid neighbours, up to the texture's
// edges (texels past them count as masked out), as over the whole texture.
TEST(Fidelity, AMaskedRenderOfASmallPlacementIsTheBilinearMeanOverValidTexels) {
  const cv::Mat texture = randomRgb(200, 150, 47);
  cv::Mat mask(150, 200, CV_8UC1, cv::Scalar(255));
  cv::circle(mask, {130, 90}, 6, cv::Scalar(0), cv::FILLED);
  cv::circle(mask, {196, 147}, 5, cv::Scalar(0), cv::FILLED);
  // cv::remap's bilinear weights are in steps of 1/32 of a texel.
  const auto expected = [&](double x_exact, double y_exact) {
    const long x32 = std::lround(x_exact * 32.0), y32 = std::lround(y_exact * 32.0);
    const auto x0 = static_cast<int>(x32 >> 5), y0 = static_cast<int>(y32 >> 5);
    const double x = x0 + static_cast<double>(x32 & 31) / 32.0;
    const double y = y0 + static_cast<double>(y32 & 31) / 32.0;
    cv::Vec3d sum(0, 0, 0);
    double weight = 0.0;
    for (int dy = 0; dy <= 1; ++dy) {
      for (int dx = 0; dx <= 1; ++dx) {
        const int tx = x0 + dx, ty = y0 + dy;
        if (tx < 0 || ty < 0 || tx >= 200 || ty >= 150 || mask.at<std::uint8_t>(ty, tx) == 0) {
          continue;
        }
        const double w = (dx ? x - x0 : 1.0 - (x - x0)) * (dy ? y - y0 : 1.0 - (y - y0));
        sum += w * cv::Vec3d(texture.at<cv::Vec3b>(ty, tx));
        weight += w;
      }
    }
    return sum / weight;
  };
  struct Placed {
    core::Similarity2 placement;
    int width, height;
  };
  // The last is taller than the strips of rows a render works in (64), and starts above the
  // texture.
  for (const auto& [placement, width, height] :
       {Placed{{1.0, 0.0, 120.3, 80.6}, 30, 20}, Placed{{0.0, 1.0, 190.0, 130.25}, 30, 20},
        Placed{{1.0, 0.0, 20.5, -10.25}, 40, 150}}) {
    const Rendered rendered = renderThrough(texture, mask, placement, width, height, false);
    int checked = 0;
    for (int r = 0; r < height; ++r) {
      for (int c = 0; c < width; ++c) {
        if (rendered.covered.at<std::uint8_t>(r, c) == 0) continue;
        const Eigen::Vector2d p = placement.apply({c, r});
        const cv::Vec3d want = expected(p.x(), p.y());
        const cv::Vec3b got = rendered.rgb.at<cv::Vec3b>(r, c);
        for (int k = 0; k < 3; ++k) EXPECT_NEAR(got[k], want[k], 1.01) << c << "," << r;
        ++checked;
      }
    }
    EXPECT_GT(checked, 200);
  }
}

TEST(Fidelity, BadInputsThrow) {
  const cv::Mat texture = randomRgb(8, 8, 46);
  EXPECT_THROW(renderThrough(cv::Mat(), {}, {}, 4, 4, false), core::Error);
  EXPECT_THROW(renderThrough(texture, cv::Mat(4, 4, CV_8UC1), {}, 4, 4, false), core::Error);
  EXPECT_THROW(renderThrough(texture, {}, {}, -1, 4, false), core::Error);
  EXPECT_THROW(measureFidelity(texture, cv::Mat(3, 3, CV_8UC1), texture, {}, {}, false),
               core::Error);
}

}  // namespace
}  // namespace tessera::match
