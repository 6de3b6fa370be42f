// PSNR, SSIM and the detail score of a render against a captured image, on a seeded texture
// whose changes are known: identical scores 1, blur weakens the detail, a shift misplaces it,
// added noise adds some, and pixels outside the mask never count.
#include "tessera/eval/image_similarity.h"

#include <random>

#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

#include "support/random_shapes.h"

namespace tessera::eval {
namespace {

constexpr int kImageWidth = 160, kImageHeight = 120;

cv::Mat shapesImage() { return test::randomShapes(kImageWidth, kImageHeight, 7); }

cv::Mat centreMask() {
  cv::Mat mask = cv::Mat::zeros(kImageHeight, kImageWidth, CV_8UC1);
  mask(cv::Rect(20, 15, 120, 90)).setTo(255);
  return mask;
}

cv::Mat withNoise(const cv::Mat& image, double sigma, unsigned seed) {
  cv::Mat noise(image.size(), CV_16SC3);
  cv::theRNG().state = seed;
  cv::randn(noise, cv::Scalar::all(0), cv::Scalar::all(sigma));
  cv::Mat wide, out;
  image.convertTo(wide, CV_16SC3);
  wide += noise;
  wide.convertTo(out, CV_8UC3);
  return out;
}

TEST(ImageSimilarity, TheSameImageScoresOneOnEveryFigure) {
  const cv::Mat image = shapesImage();
  const auto s = compareImages(image, image, centreMask());
  ASSERT_TRUE(s);
  EXPECT_DOUBLE_EQ(s->psnr_db, 99.0);
  EXPECT_NEAR(s->ssim, 1.0, 1e-6);
  EXPECT_NEAR(s->detail_correlation, 1.0, 1e-9);
  EXPECT_NEAR(s->detail_energy_ratio, 1.0, 1e-9);
  EXPECT_NEAR(s->detail, 1.0, 1e-9);
}

TEST(ImageSimilarity, BlurWeakensTheDetailAndAShiftMisplacesIt) {
  const cv::Mat image = shapesImage(), mask = centreMask();
  cv::Mat blurred;
  cv::GaussianBlur(image, blurred, cv::Size(), 1.5);
  const auto blur = *compareImages(blurred, image, mask);
  EXPECT_LT(blur.detail_energy_ratio, 0.6);  // the band-pass lost much of its energy
  EXPECT_GT(blur.detail_correlation, 0.7);   // what is left is in its place
  EXPECT_LT(blur.detail, 0.7);
  EXPECT_LT(blur.ssim, 0.95);

  cv::Mat shifted;
  const cv::Mat move = (cv::Mat_<double>(2, 3) << 1, 0, 3, 0, 1, 0);
  cv::warpAffine(image, shifted, move, image.size(), cv::INTER_NEAREST, cv::BORDER_REFLECT);
  const auto shift = *compareImages(shifted, image, mask);
  EXPECT_NEAR(shift.detail_energy_ratio, 1.0, 0.1);  // as much detail, in the wrong place
  EXPECT_LT(shift.detail_correlation, 0.3);
  EXPECT_LT(shift.detail, blur.detail);
  EXPECT_LT(shift.ssim, blur.ssim);
}

TEST(ImageSimilarity, AddedNoiseAddsDetailEnergyAndLowersTheScore) {
  const cv::Mat image = shapesImage(), mask = centreMask();
  const auto noisy = *compareImages(withNoise(image, 20.0, 11), image, mask);
  EXPECT_GT(noisy.detail_energy_ratio, 1.05);
  EXPECT_LT(noisy.detail, 0.95);
  EXPECT_LT(noisy.psnr_db, 30.0);
}

TEST(ImageSimilarity, PixelsOutsideTheMaskNeverCount) {
  const cv::Mat image = shapesImage(), mask = centreMask();
  cv::Mat changed = image.clone();
  cv::Mat outside;
  cv::bitwise_not(mask, outside);
  changed.setTo(cv::Scalar(255, 0, 255), outside);
  const auto a = *compareImages(image, image, mask);
  const auto b = *compareImages(changed, image, mask);
  EXPECT_DOUBLE_EQ(a.psnr_db, b.psnr_db);
  EXPECT_NEAR(a.ssim, b.ssim, 1e-6);
  EXPECT_NEAR(a.detail, b.detail, 1e-6);
  EXPECT_FALSE(compareImages(image, image, cv::Mat::zeros(kImageHeight, kImageWidth, CV_8UC1)));
}

}  // namespace
}  // namespace tessera::eval
