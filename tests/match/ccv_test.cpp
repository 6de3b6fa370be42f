// Colour coherence vectors: hand-computed vectors on tiny images, the case plain histograms
// cannot tell apart, masks, and invariance to image size and exposure.
#include "tessera/match/ccv.h"

#include <random>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

#include "tessera/core/error.h"

namespace tessera::match {
namespace {

const cv::Vec3b kRed(255, 0, 0), kBlue(0, 0, 255);

// Two levels per channel: bin = 4 r + 2 g + b, each in {0, 1}. Red is bin 4, blue bin 1.
constexpr std::size_t kRedBin = 4, kBlueBin = 1, kBins = 8;

CcvConfig exactConfig(int min_coherent_px) {
  CcvConfig config;
  config.blur_sigma_px = 0.0;
  config.levels = 2;
  config.coherent_fraction = 0.0;
  config.min_coherent_px = min_coherent_px;
  config.normalise_exposure = false;
  return config;
}

// The colour histogram a CCV implies (alpha + beta per bin).
std::vector<float> histogramOf(const Ccv& ccv) {
  const std::size_t bins = ccv.values.size() / 2;
  std::vector<float> h(bins);
  for (std::size_t i = 0; i < bins; ++i) h[i] = ccv.values[i] + ccv.values[bins + i];
  return h;
}

// Random filled shapes of random colours on a 0..190 background (no channel clips at x1.3).
cv::Mat randomShapes(int width, int height, unsigned seed) {
  std::mt19937 random(seed);
  std::uniform_int_distribution<int> colour(0, 190), x(0, width - 1), y(0, height - 1),
      radius(4, 30);
  cv::Mat image(height, width, CV_8UC3, cv::Scalar(colour(random), colour(random), colour(random)));
  for (int i = 0; i < 60; ++i) {
    const cv::Scalar c(colour(random), colour(random), colour(random));
    if (i % 2 == 0) {
      cv::circle(image, {x(random), y(random)}, radius(random), c, cv::FILLED);
    } else {
      const cv::Point corner(x(random), y(random));
      cv::rectangle(image, corner, corner + cv::Point(radius(random), radius(random)), c,
                    cv::FILLED);
    }
  }
  return image;
}

TEST(Ccv, HandComputedVectorsOfABlockAndOfScatteredPixelsWithEqualHistograms) {
  // Both 6 x 6, 9 red and 27 blue pixels. Block: the reds form one 3 x 3 component.
  // Scattered: reds at even (row, col), no two 8-adjacent, so nine components of one pixel.
  cv::Mat block(6, 6, CV_8UC3, cv::Scalar(kBlue)), scattered = block.clone();
  block(cv::Rect(0, 0, 3, 3)).setTo(cv::Scalar(kRed));
  for (int r = 0; r < 6; r += 2) {
    for (int c = 0; c < 6; c += 2) scattered.at<cv::Vec3b>(r, c) = kRed;
  }
  const CcvConfig config = exactConfig(4);
  const Ccv a = computeCcv(block, {}, config);
  const Ccv b = computeCcv(scattered, {}, config);
  ASSERT_EQ(a.values.size(), 2 * kBins);
  EXPECT_EQ(a.pixels, 36u);

  std::vector<float> expected_a(2 * kBins, 0.0F), expected_b(2 * kBins, 0.0F);
  expected_a[kRedBin] = 9.0F / 36;          // alpha: coherent red
  expected_a[kBlueBin] = 27.0F / 36;        // the blue L shape is one component
  expected_b[kBins + kRedBin] = 9.0F / 36;  // beta: incoherent red
  expected_b[kBlueBin] = 27.0F / 36;        // blue still connects diagonally
  for (std::size_t i = 0; i < 2 * kBins; ++i) {
    EXPECT_FLOAT_EQ(a.values[i], expected_a[i]) << "bin " << i;
    EXPECT_FLOAT_EQ(b.values[i], expected_b[i]) << "bin " << i;
  }
  EXPECT_DOUBLE_EQ(ccvDistance(histogramOf(a), histogramOf(b)), 0.0);
  EXPECT_NEAR(ccvDistance(a.values, b.values), 0.5, 1e-6);
}

TEST(Ccv, AComponentOfExactlySPixelsIsCoherent) {
  cv::Mat image(6, 6, CV_8UC3, cv::Scalar(kBlue));
  image(cv::Rect(0, 0, 2, 2)).setTo(cv::Scalar(kRed));  // 4 red pixels
  EXPECT_FLOAT_EQ(computeCcv(image, {}, exactConfig(4)).values[kRedBin], 4.0F / 36);
  EXPECT_FLOAT_EQ(computeCcv(image, {}, exactConfig(5)).values[kBins + kRedBin], 4.0F / 36);
}

TEST(Ccv, MaskedPixelsCountNowhereAndSplitComponents) {
  // All red, column 2 masked out: components of 12 (columns 0-1) and 18 (columns 3-5) pixels.
  cv::Mat image(6, 6, CV_8UC3, cv::Scalar(kRed));
  cv::Mat mask(6, 6, CV_8UC1, cv::Scalar(255));
  mask.col(2).setTo(0);
  image.col(2).setTo(cv::Scalar(kBlue));  // hidden by the mask
  const Ccv ccv = computeCcv(image, mask, exactConfig(13));
  EXPECT_EQ(ccv.pixels, 30u);
  EXPECT_FLOAT_EQ(ccv.values[kRedBin], 18.0F / 30);
  EXPECT_FLOAT_EQ(ccv.values[kBins + kRedBin], 12.0F / 30);
  EXPECT_FLOAT_EQ(ccv.values[kBlueBin], 0.0F);
  EXPECT_FLOAT_EQ(ccv.values[kBins + kBlueBin], 0.0F);

  // Whatever lies under the mask changes nothing, with the default (blurred) config too.
  cv::Mat other = randomShapes(80, 60, 5), changed = other.clone();
  cv::Mat half(60, 80, CV_8UC1, cv::Scalar(0));
  half(cv::Rect(0, 0, 40, 60)).setTo(255);
  changed(cv::Rect(40, 0, 40, 60)).setTo(cv::Scalar(10, 250, 30));
  EXPECT_EQ(computeCcv(other, half).values, computeCcv(changed, half).values);
  EXPECT_EQ(computeCcv(other, cv::Mat::zeros(60, 80, CV_8UC1)).pixels, 0u);
}

TEST(Ccv, DistanceIsZeroToItselfSmallAcrossSizesAndLargeToAnotherImage) {
  const cv::Mat image = randomShapes(160, 120, 1);
  const cv::Mat unrelated = randomShapes(160, 120, 2);
  cv::Mat upscaled;
  cv::resize(image, upscaled, cv::Size(), 2.0, 2.0, cv::INTER_LINEAR);
  // Coherence as a share of the image (Pass et al.), so that a blob scaled with its image
  // stays coherent; the blur scales with it too.
  CcvConfig config;
  config.coherent_fraction = 0.01;
  CcvConfig upscaled_config = config;
  upscaled_config.blur_sigma_px *= 2.0;
  const Ccv ccv = computeCcv(image, {}, config);
  EXPECT_DOUBLE_EQ(ccvDistance(ccv.values, computeCcv(image, {}, config).values), 0.0);
  const double across_sizes =
      ccvDistance(ccv.values, computeCcv(upscaled, {}, upscaled_config).values);
  const double to_other = ccvDistance(ccv.values, computeCcv(unrelated, {}, config).values);
  EXPECT_LT(across_sizes, 0.15);
  EXPECT_GT(to_other, 1.0);
}

TEST(Ccv, ExposureNormalisationKeepsAGainChangedCopyClose) {
  const cv::Mat image = randomShapes(160, 120, 3);
  cv::Mat brighter;
  image.convertTo(brighter, CV_8UC3, 1.3);
  CcvConfig config;
  const double normalised =
      ccvDistance(computeCcv(image, {}, config).values, computeCcv(brighter, {}, config).values);
  config.normalise_exposure = false;
  const double raw =
      ccvDistance(computeCcv(image, {}, config).values, computeCcv(brighter, {}, config).values);
  EXPECT_LT(normalised, 0.15);
  EXPECT_GT(raw, 3 * normalised);  // the normalisation is what keeps it close
}

// The definition, one colour bin at a time: its pixels labelled by OpenCV (8-neighbours), the
// components of at least s pixels coherent. Levels 4, no blur, no exposure normalisation.
std::vector<float> ccvOneBinAtATime(const cv::Mat& rgb, const cv::Mat& mask, int s) {
  cv::Mat bins(rgb.size(), CV_32SC1, cv::Scalar(-1));
  for (int y = 0; y < rgb.rows; ++y) {
    for (int x = 0; x < rgb.cols; ++x) {
      if (mask.at<std::uint8_t>(y, x) == 0) continue;
      const cv::Vec3b p = rgb.at<cv::Vec3b>(y, x);
      bins.at<int>(y, x) = (p[0] / 64) * 16 + (p[1] / 64) * 4 + p[2] / 64;
    }
  }
  const double n = cv::countNonZero(mask);
  std::vector<float> values(128, 0.0F);
  for (int bin = 0; bin < 64; ++bin) {
    const cv::Mat members = bins == bin;
    cv::Mat labels, stats, centroids;
    const int count = cv::connectedComponentsWithStats(members, labels, stats, centroids, 8);
    std::size_t coherent = 0, all = 0;
    for (int label = 1; label < count; ++label) {
      const auto area = static_cast<std::size_t>(stats.at<int>(label, cv::CC_STAT_AREA));
      all += area;
      if (area >= static_cast<std::size_t>(s)) coherent += area;
    }
    values[static_cast<std::size_t>(bin)] = static_cast<float>(static_cast<double>(coherent) / n);
    values[static_cast<std::size_t>(64 + bin)] =
        static_cast<float>(static_cast<double>(all - coherent) / n);
  }
  return values;
}

// The one-pass labelling gives the definition's vector exactly, on shapes sprinkled with
// single-pixel noise (many small components, diagonal contacts) under a mask with holes.
TEST(Ccv, EqualsTheDefinitionComputedOneBinAtATime) {
  for (unsigned seed = 1; seed <= 4; ++seed) {
    cv::Mat image = randomShapes(173, 131, seed);
    std::mt19937 random(seed);
    std::uniform_int_distribution<int> x(0, image.cols - 1), y(0, image.rows - 1), level(0, 255);
    for (int i = 0; i < 3000; ++i) {
      image.at<cv::Vec3b>(y(random), x(random)) = cv::Vec3b(
          static_cast<std::uint8_t>(level(random)), static_cast<std::uint8_t>(level(random)),
          static_cast<std::uint8_t>(level(random)));
    }
    cv::Mat mask(image.size(), CV_8UC1, cv::Scalar(255));
    cv::circle(mask, {x(random), y(random)}, 25, cv::Scalar(0), cv::FILLED);
    cv::rectangle(mask, {0, 40}, {image.cols - 1, 44}, cv::Scalar(0), cv::FILLED);
    for (const int s : {1, 3, 50}) {
      CcvConfig config = exactConfig(s);
      config.levels = 4;
      EXPECT_EQ(computeCcv(image, mask, config).values, ccvOneBinAtATime(image, mask, s))
          << "seed " << seed << ", s " << s;
    }
  }
}

TEST(Ccv, BadInputsThrow) {
  EXPECT_THROW(computeCcv(cv::Mat(), {}), core::Error);
  EXPECT_THROW(computeCcv(cv::Mat(4, 4, CV_8UC1, cv::Scalar(0)), {}), core::Error);
  EXPECT_THROW(computeCcv(cv::Mat(4, 4, CV_8UC3, cv::Scalar::all(0)), cv::Mat(3, 4, CV_8UC1)),
               core::Error);
  EXPECT_THROW(ccvDistance({1.0F, 2.0F}, {1.0F}), core::Error);
}

}  // namespace
}  // namespace tessera::match
