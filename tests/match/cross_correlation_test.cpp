// Normalised cross-correlation: a known tile is found at its offset, through noise and a local
// change of brightness and contrast; the fast map agrees with the textbook formula.
#include "tessera/match/cross_correlation.h"

#include <cmath>
#include <random>

#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

#include "tessera/core/error.h"

namespace tessera::match {
namespace {

// Grey texture in 0..255, lightly blurred so it has structure beyond single pixels.
cv::Mat randomTexture(int width, int height, std::mt19937& random) {
  std::uniform_real_distribution<float> level(0.0F, 255.0F);
  cv::Mat texture(height, width, CV_32FC1);
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) texture.at<float>(y, x) = level(random);
  }
  cv::GaussianBlur(texture, texture, cv::Size(), 1.0);
  return texture;
}

void addNoise(cv::Mat& image, float sigma, std::mt19937& random) {
  std::normal_distribution<float> noise(0.0F, sigma);
  for (auto it = image.begin<float>(); it != image.end<float>(); ++it) *it += noise(random);
}

// The textbook zero-mean NCC of `tile` placed at (x, y): the slow reference.
double referenceNcc(const cv::Mat& image, const cv::Mat& tile, int x, int y) {
  const cv::Mat window = image(cv::Rect(x, y, tile.cols, tile.rows));
  const double mw = cv::mean(window)[0], mt = cv::mean(tile)[0];
  double cross = 0.0, ww = 0.0, tt = 0.0;
  for (int r = 0; r < tile.rows; ++r) {
    for (int c = 0; c < tile.cols; ++c) {
      const double w = window.at<float>(r, c) - mw, t = tile.at<float>(r, c) - mt;
      cross += w * t;
      ww += w * w;
      tt += t * t;
    }
  }
  return cross / std::sqrt(ww * tt);
}

TEST(CrossCorrelation, AKnownTileIsFoundAtItsOffsetThroughNoise) {
  std::mt19937 random(21);
  cv::Mat image = randomTexture(200, 160, random);
  const cv::Mat tile = randomTexture(40, 36, random);
  tile.copyTo(image(cv::Rect(73, 51, tile.cols, tile.rows)));
  addNoise(image, 5.0F, random);
  const CorrelationPeak peak = findTile(image, tile);
  EXPECT_EQ(peak.x, 73);
  EXPECT_EQ(peak.y, 51);
  EXPECT_GT(peak.score, 0.9);

  const cv::Mat stranger = randomTexture(40, 36, random);
  EXPECT_LT(findTile(image, stranger).score, 0.5);
}

TEST(CrossCorrelation, NormalisationPerWindowFindsATileUnderABrightnessGradient) {
  std::mt19937 random(22);
  cv::Mat image = randomTexture(200, 160, random);
  const cv::Mat tile = randomTexture(40, 36, random);
  // Half the contrast and 40 brighter where the tile lies, and a ramp of 0..80 across the
  // whole image: a single global mean and spread would describe none of the windows. The ramp
  // still adds 16 levels of slope inside the tile's window, so the peak stays below 1.
  tile.convertTo(image(cv::Rect(120, 90, tile.cols, tile.rows)), CV_32F, 0.5, 40.0);
  for (int y = 0; y < image.rows; ++y) {
    for (int x = 0; x < image.cols; ++x) image.at<float>(y, x) += 0.4F * static_cast<float>(x);
  }
  addNoise(image, 3.0F, random);
  const CorrelationPeak peak = findTile(image, tile);
  EXPECT_EQ(peak.x, 120);
  EXPECT_EQ(peak.y, 90);
  EXPECT_GT(peak.score, 0.85);
}

TEST(CrossCorrelation, TheMapAgreesWithTheTextbookFormula) {
  std::mt19937 random(23);
  const cv::Mat image = randomTexture(64, 48, random);
  const cv::Mat tile = randomTexture(16, 12, random);
  const cv::Mat ncc = normalisedCrossCorrelation(image, tile);
  ASSERT_EQ(ncc.size(), cv::Size(49, 37));
  for (const cv::Point at :
       {cv::Point(0, 0), cv::Point(48, 36), cv::Point(17, 5), cv::Point(30, 29)}) {
    EXPECT_NEAR(ncc.at<float>(at), referenceNcc(image, tile, at.x, at.y), 1e-4) << at;
  }
}

TEST(CrossCorrelation, ATurnedTileIsFoundAtItsTurnWithTheScoresOfEachTurnAlone) {
  std::mt19937 random(25);
  const cv::Mat tile = randomTexture(40, 36, random);
  for (int turns = 0; turns < 4; ++turns) {
    cv::Mat image = randomTexture(200, 160, random);
    const cv::Mat placed = turned(tile, turns);
    placed.copyTo(image(cv::Rect(73, 51, placed.cols, placed.rows)));
    addNoise(image, 5.0F, random);
    const TurnedPeak found = findTileAtAnyTurn(image, tile);
    EXPECT_EQ(found.turns, turns);
    EXPECT_EQ(found.peak.x, 73);
    EXPECT_EQ(found.peak.y, 51);
    EXPECT_NEAR(found.peak.score, referenceNcc(image, placed, 73, 51), 1e-4);
    // Turns 2 and 3 come from the convolution with turns 0 and 1: their score is the textbook
    // one above, and no other turn scores as high.
    for (int other = 0; other < 4; ++other) {
      const CorrelationPeak alone = findTile(image, turned(tile, other));
      if (other != turns) {
        EXPECT_LT(alone.score, found.peak.score) << turns << " " << other;
      }
    }
  }
  // Too large at every turn: no placement.
  EXPECT_EQ(findTileAtAnyTurn(randomTexture(30, 30, random), tile).peak.score, -1.0);
}

TEST(CrossCorrelation, FlatWindowsAndFlatTilesScoreZero) {
  std::mt19937 random(24);
  cv::Mat image(60, 80, CV_32FC1, cv::Scalar(100.0F));
  randomTexture(40, 60, random).copyTo(image(cv::Rect(40, 0, 40, 60)));
  const cv::Mat tile = randomTexture(10, 10, random);
  const cv::Mat ncc = normalisedCrossCorrelation(image, tile);
  for (int y = 0; y < ncc.rows; ++y) {
    for (int x = 0; x <= 30; ++x) EXPECT_EQ(ncc.at<float>(y, x), 0.0F) << x << "," << y;
  }
  const cv::Mat flat(10, 10, CV_32FC1, cv::Scalar(7.0F));
  EXPECT_EQ(cv::countNonZero(normalisedCrossCorrelation(image, flat)), 0);
  EXPECT_EQ(findTile(image, flat).score, 0.0);
}

TEST(CrossCorrelation, GreyOutsideTheMaskIsTheMeanInside) {
  cv::Mat rgb(4, 4, CV_8UC3, cv::Scalar(0, 0, 0));
  rgb(cv::Rect(0, 0, 2, 4)).setTo(cv::Scalar(100, 100, 100));
  rgb(cv::Rect(2, 0, 1, 4)).setTo(cv::Scalar(200, 200, 200));
  cv::Mat mask(4, 4, CV_8UC1, cv::Scalar(255));
  mask.col(3).setTo(0);
  const cv::Mat grey = greyForCorrelation(rgb, mask);
  ASSERT_EQ(grey.type(), CV_32FC1);
  EXPECT_NEAR(grey.at<float>(0, 0), 100.0F, 1e-3F);
  EXPECT_NEAR(grey.at<float>(2, 2), 200.0F, 1e-3F);
  EXPECT_NEAR(grey.at<float>(1, 3), 400.0F / 3.0F, 1e-3F);  // mean of 100, 100, 200
  EXPECT_NEAR(greyForCorrelation(rgb, {}).at<float>(1, 3), 0.0F, 1e-3F);
}

TEST(CrossCorrelation, TwoCropsThatOverlapInPartAreRegisteredOverTheirCommonTexels) {
  // Two crops of one texture, neither inside the other, the second's origin at (123, 81) in
  // the first's frame; a masked-out blob in each. Found on the images scaled by 1/3 and made
  // exact at full size.
  std::mt19937 random(17);
  const cv::Mat big = randomTexture(420, 300, random);
  cv::Mat a = big(cv::Rect(0, 0, 300, 200)).clone(), b = big(cv::Rect(123, 81, 297, 219)).clone();
  addNoise(a, 4.0F, random);
  addNoise(b, 4.0F, random);
  cv::Mat mask_a(a.size(), CV_8UC1, cv::Scalar(255)), mask_b(b.size(), CV_8UC1, cv::Scalar(255));
  cv::circle(mask_a, {60, 150}, 30, cv::Scalar(0), cv::FILLED);
  cv::circle(mask_b, {100, 60}, 25, cv::Scalar(0), cv::FILLED);
  // Texels outside the masks are garbage: they must not count.
  a.setTo(0.0F, mask_a == 0);
  b.setTo(255.0F, mask_b == 0);

  cv::Mat small_a, small_b, small_mask_a, small_mask_b;
  cv::resize(a, small_a, cv::Size(), 1.0 / 3, 1.0 / 3, cv::INTER_AREA);
  cv::resize(b, small_b, cv::Size(), 1.0 / 3, 1.0 / 3, cv::INTER_AREA);
  cv::resize(mask_a, small_mask_a, small_a.size(), 0, 0, cv::INTER_NEAREST);
  cv::resize(mask_b, small_mask_b, small_b.size(), 0, 0, cv::INTER_NEAREST);
  const CorrelationPeak coarse = findOverlap(small_a, small_mask_a, small_b, small_mask_b, 500.0);
  EXPECT_NEAR(coarse.x, 41, 1);
  EXPECT_NEAR(coarse.y, 27, 1);
  const CorrelationPeak exact =
      refineOverlap(a, mask_a, b, mask_b, {3 * coarse.x, 3 * coarse.y, coarse.score}, 4, 5000.0);
  EXPECT_EQ(exact.x, 123);
  EXPECT_EQ(exact.y, 81);
  EXPECT_GT(exact.score, 0.9);

  // At full size the DFT search agrees with the direct score at its peak.
  const CorrelationPeak full = findOverlap(a, mask_a, b, mask_b, 5000.0);
  EXPECT_EQ(full.x, 123);
  EXPECT_EQ(full.y, 81);
  EXPECT_NEAR(full.score, exact.score, 1e-6);

  // Unrelated textures overlap nowhere well.
  const cv::Mat other = randomTexture(297, 219, random);
  EXPECT_LT(findOverlap(a, mask_a, other, mask_b, 5000.0).score, 0.3);
  // And a demanded overlap larger than any placement gives leaves no placement.
  EXPECT_EQ(findOverlap(a, mask_a, b, mask_b, 1e6).score, -1.0);
}

TEST(CrossCorrelation, AnOverlapIsFoundAtEveryQuarterTurnAsOnTheTurnedImage) {
  // The second crop stored turned: each turn is found with the shift and score that the search
  // of the image turned back gives, although two turns share one set of DFTs.
  std::mt19937 random(31);
  const cv::Mat big = randomTexture(150, 110, random);
  const cv::Mat a = big(cv::Rect(0, 0, 100, 70)).clone();
  const cv::Mat b = big(cv::Rect(37, 22, 90, 80)).clone();
  const cv::Mat mask_a(a.size(), CV_8UC1, cv::Scalar(255));
  cv::Mat mask_b(b.size(), CV_8UC1, cv::Scalar(255));
  cv::circle(mask_b, {20, 60}, 12, cv::Scalar(0), cv::FILLED);
  for (int turns = 0; turns < 4; ++turns) {
    // b stored turned back by `turns`: turning it by `turns` gives b upright.
    const cv::Mat stored = turned(b, (4 - turns) % 4),
                  stored_mask = turned(mask_b, (4 - turns) % 4);
    const TurnedPeak found = findOverlapAtAnyTurn(a, mask_a, stored, stored_mask, 1000.0);
    EXPECT_EQ(found.turns, turns);
    EXPECT_EQ(found.peak.x, 37) << turns;
    EXPECT_EQ(found.peak.y, 22) << turns;
    const CorrelationPeak direct = findOverlap(a, mask_a, b, mask_b, 1000.0);
    EXPECT_NEAR(found.peak.score, direct.score, 1e-5) << turns;
    EXPECT_GT(found.peak.score, 0.999) << turns;
  }
  EXPECT_EQ(findOverlapAtAnyTurn(a, mask_a, b, mask_b, 1e6).peak.score, -1.0);
}

TEST(CrossCorrelation, BadInputsThrow) {
  const cv::Mat small(8, 8, CV_32FC1, cv::Scalar(0.0F)), large(9, 8, CV_32FC1, cv::Scalar(0.0F));
  EXPECT_THROW(normalisedCrossCorrelation(small, large), core::Error);
  EXPECT_THROW(normalisedCrossCorrelation(cv::Mat(8, 8, CV_8UC1), small), core::Error);
  EXPECT_THROW(greyForCorrelation(cv::Mat(), {}), core::Error);
}

}  // namespace
}  // namespace tessera::match
