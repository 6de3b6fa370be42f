#include <random>

#include <gtest/gtest.h>

#include <opencv2/imgproc.hpp>

#include "tessera/core/error.h"
#include "tessera/planes/frame_sharpness.h"
#include "tessera/texture/bitmap_builder.h"

namespace tessera::texture {
namespace {

using planes::ColourSample;

planes::PatchSnapshot rectanglePatch(double width_m, double height_m) {
  planes::PatchSnapshot patch;
  patch.id = 7;
  patch.version = 1;
  patch.outline.parts.push_back({{{0, 0}, {width_m, 0}, {width_m, height_m}, {0, height_m}}, {}});
  return patch;
}

// A smooth colour field over the plane, what the samples observe.
cv::Vec3b fieldAt(double u, double v) {
  return {cv::saturate_cast<std::uint8_t>(128 + 100 * std::sin(u * 20)),
          cv::saturate_cast<std::uint8_t>(128 + 100 * std::cos(v * 15)),
          cv::saturate_cast<std::uint8_t>(60 + 150 * u)};
}

// Samples of the field at random positions, two per 5 mm cell on average, with random scores.
void addRandomSamples(planes::PatchSnapshot& patch, double width_m, double height_m,
                      std::uint32_t seed) {
  std::mt19937 random(seed);
  std::uniform_real_distribution<double> u_at(0.0, width_m), v_at(0.0, height_m);
  std::uniform_real_distribution<float> score_of(-3.0F, 0.0F);
  const auto count = static_cast<std::size_t>(2.0 * width_m * height_m / 25e-6);
  for (std::size_t i = 0; i < count; ++i) {
    ColourSample s;
    s.u = static_cast<float>(u_at(random));
    s.v = static_cast<float>(v_at(random));
    const cv::Vec3b colour = fieldAt(s.u, s.v);
    s.rgb = {colour[0], colour[1], colour[2]};
    s.score = score_of(random);
    patch.samples.push_back(s);
  }
}

TEST(BitmapBuilder, BucketedAveragingMatchesTheBruteForceReference) {
  planes::PatchSnapshot patch = rectanglePatch(0.2, 0.15);
  addRandomSamples(patch, 0.2, 0.15, 42);
  BitmapConfig config;
  config.texel_m = 0.005;
  config.max_inpaint_texels = 0;
  for (const bool best_view : {false, true}) {
    config.best_view = best_view;
    const PatchBitmap fast = buildBitmap(patch, config);
    const PatchBitmap slow = buildBitmapBruteForce(patch, config);
    ASSERT_EQ(fast.image.size(), slow.image.size());
    EXPECT_EQ(fast.observed, slow.observed);
    EXPECT_GT(static_cast<double>(fast.observed), 0.95 * static_cast<double>(fast.grid.texels()));
    EXPECT_EQ(cv::countNonZero(fast.state != slow.state), 0);
    cv::Mat difference;
    cv::absdiff(fast.image, slow.image, difference);
    double worst = 0.0;
    cv::minMaxLoc(difference.reshape(1), nullptr, &worst);
    EXPECT_LE(worst, 1.0) << "best_view " << best_view;  // rounding of the weighted mean only
  }
}

// Few samples over a large patch (the index widens its buckets), some outside the outline.
TEST(BitmapBuilder, SparseSamplesFindTheSameNeighboursAsTheBruteForceReference) {
  planes::PatchSnapshot patch = rectanglePatch(10.0, 8.0);
  std::mt19937 random(3);
  std::uniform_real_distribution<double> u_at(-0.5, 10.5), v_at(-0.5, 8.5);
  for (int i = 0; i < 600; ++i) {
    ColourSample s;
    s.u = static_cast<float>(u_at(random));
    s.v = static_cast<float>(v_at(random));
    const cv::Vec3b colour = fieldAt(s.u, s.v);
    s.rgb = {colour[0], colour[1], colour[2]};
    s.score = static_cast<float>(i % 5) * -0.5F;
    patch.samples.push_back(s);
  }
  BitmapConfig config;
  config.texel_m = 0.1;
  config.neighbours = 2;  // fewer than the samples in reach: the nearest must be the ones taken
  config.max_inpaint_texels = 0;
  const PatchBitmap fast = buildBitmap(patch, config);
  const PatchBitmap slow = buildBitmapBruteForce(patch, config);
  EXPECT_GT(fast.observed, fast.grid.texels() / 5);
  EXPECT_LT(fast.observed, fast.grid.texels());
  EXPECT_EQ(fast.observed, slow.observed);
  EXPECT_EQ(cv::countNonZero(fast.state != slow.state), 0);
  cv::Mat difference;
  cv::absdiff(fast.image, slow.image, difference);
  double worst = 0.0;
  cv::minMaxLoc(difference.reshape(1), nullptr, &worst);
  EXPECT_LE(worst, 1.0);
}

TEST(BitmapBuilder, ASmoothFieldIsReproducedAtTheTexelCentres) {
  planes::PatchSnapshot patch = rectanglePatch(0.3, 0.2);
  addRandomSamples(patch, 0.3, 0.2, 7);
  BitmapConfig config;
  config.texel_m = 0.005;
  const PatchBitmap bitmap = buildBitmap(patch, config);
  double squared = 0.0;
  std::size_t counted = 0;
  for (int r = 0; r < bitmap.grid.height; ++r) {
    for (int c = 0; c < bitmap.grid.width; ++c) {
      if (bitmap.state.at<std::uint8_t>(r, c) != static_cast<int>(TexelState::kObserved)) continue;
      const Eigen::Vector2d uv = bitmap.grid.uvOf(c + 0.5, r + 0.5);
      const cv::Vec3b truth = fieldAt(uv.x(), uv.y());
      for (int k = 0; k < 3; ++k)
        squared += std::pow(bitmap.image.at<cv::Vec3b>(r, c)[k] - truth[k], 2);
      counted += 3;
    }
  }
  ASSERT_GT(counted, 0u);
  // The field changes by at most 2 levels per mm; samples lie within one texel of the centre.
  EXPECT_LT(std::sqrt(squared / static_cast<double>(counted)), 3.0);
}

TEST(BitmapBuilder, SmallHolesAreInpaintedAndMarkedLargeOnesStayEmpty) {
  planes::PatchSnapshot patch = rectanglePatch(0.4, 0.3);
  addRandomSamples(patch, 0.4, 0.3, 3);
  // Remove the samples in a 1 cm square (4 texels) and in a 6 cm square (144 texels).
  auto in = [](const ColourSample& s, double u0, double v0, double side) {
    return s.u >= u0 && s.u < u0 + side && s.v >= v0 && s.v < v0 + side;
  };
  std::erase_if(patch.samples, [&](const ColourSample& s) {
    return in(s, 0.1, 0.1, 0.012) || in(s, 0.25, 0.15, 0.06);
  });
  BitmapConfig config;
  config.texel_m = 0.005;
  config.radius_texels = 0.75;
  const PatchBitmap bitmap = buildBitmap(patch, config);
  auto stateAt = [&](double u, double v) {
    const Eigen::Vector2d d = Eigen::Vector2d(u, v) - bitmap.grid.origin_uv;
    const int col = static_cast<int>(d.dot(bitmap.grid.x_axis) / bitmap.grid.texel_m);
    const int row = static_cast<int>(d.dot(bitmap.grid.y_axis) / bitmap.grid.texel_m);
    return static_cast<TexelState>(bitmap.state.at<std::uint8_t>(row, col));
  };
  EXPECT_EQ(stateAt(0.106, 0.106), TexelState::kInpainted);
  EXPECT_EQ(stateAt(0.28, 0.18), TexelState::kEmpty);
  EXPECT_EQ(stateAt(0.05, 0.05), TexelState::kObserved);
  // Nothing of the large hole's inside is filled (single missing texels elsewhere, where the
  // random samples left a gap, may be).
  for (double u = 0.257; u < 0.303; u += 0.005) {
    for (double v = 0.157; v < 0.203; v += 0.005) EXPECT_EQ(stateAt(u, v), TexelState::kEmpty);
  }
  EXPECT_GT(bitmap.inpainted, 0u);
  // The inpainted colour continues its surroundings.
  const Eigen::Vector2d d = Eigen::Vector2d(0.106, 0.106) - bitmap.grid.origin_uv;
  const cv::Vec3b filled =
      bitmap.image.at<cv::Vec3b>(static_cast<int>(d.dot(bitmap.grid.y_axis) / 0.005),
                                 static_cast<int>(d.dot(bitmap.grid.x_axis) / 0.005));
  const cv::Vec3b truth = fieldAt(0.106, 0.106);
  for (int k = 0; k < 3; ++k) EXPECT_NEAR(filled[k], truth[k], 12);
}

TEST(BitmapBuilder, TheHeavierViewWinsTheAverage) {
  planes::PatchSnapshot patch = rectanglePatch(0.05, 0.05);
  // Two views of every spot: red from a good view, blue from one e^3 times lighter.
  for (double u = 0.001; u < 0.05; u += 0.0025) {
    for (double v = 0.001; v < 0.05; v += 0.0025) {
      patch.samples.push_back({static_cast<float>(u), static_cast<float>(v), {200, 0, 0}, 0.0F});
      patch.samples.push_back({static_cast<float>(u), static_cast<float>(v), {0, 0, 200}, -3.0F});
    }
  }
  BitmapConfig config;
  config.texel_m = 0.005;
  const PatchBitmap average = buildBitmap(patch, config);
  const cv::Vec3b mixed = average.image.at<cv::Vec3b>(5, 5);
  EXPECT_NEAR(mixed[0], 200.0 / (1.0 + std::exp(-3.0)), 2.0);
  EXPECT_NEAR(mixed[2], 200.0 * std::exp(-3.0) / (1.0 + std::exp(-3.0)), 2.0);
  config.best_view = true;
  const cv::Vec3b best = buildBitmap(patch, config).image.at<cv::Vec3b>(5, 5);
  EXPECT_EQ(best, cv::Vec3b(200, 0, 0));
}

TEST(BitmapBuilder, AutomaticTexelSizeFollowsThePixelFootprint) {
  planes::PatchSnapshot patch = rectanglePatch(0.1, 0.1);
  BitmapConfig config;
  patch.pixel_footprint_m = 2.0 / 525.0;
  EXPECT_NEAR(texelSizeFor(patch, config), 0.00381, 1e-5);
  patch.pixel_footprint_m = 0.5;
  EXPECT_EQ(texelSizeFor(patch, config), config.max_texel_m);
  config.texel_m = 0.004;
  EXPECT_EQ(texelSizeFor(patch, config), 0.004);
}

TEST(SharpnessGauge, AMotionBlurredFrameCountsForLess) {
  std::mt19937 random(5);
  cv::Mat sharp(240, 320, CV_8UC3);
  cv::randu(sharp, 0, 255);
  cv::GaussianBlur(sharp, sharp, cv::Size(0, 0), 1.0);
  planes::SharpnessGauge gauge;
  for (int i = 0; i < 10; ++i) EXPECT_DOUBLE_EQ(gauge.measure(sharp), 1.0);
  cv::Mat blurred;
  const cv::Mat streak = cv::Mat::ones(1, 9, CV_32F) / 9.0;  // a 9-pixel horizontal motion
  cv::filter2D(sharp, blurred, -1, streak);
  const double factor = gauge.measure(blurred);
  EXPECT_LT(factor, 0.5);
  EXPECT_GE(factor, planes::SharpnessGauge::kFloor);
  EXPECT_DOUBLE_EQ(gauge.measure(sharp), 1.0);
}

}  // namespace
}  // namespace tessera::texture

namespace tessera::texture {
namespace {

TEST(BitmapConfig, OutOfRangeValuesAreRejected) {
  for (const char* yaml : {"texel_m: 0.0001", "min_texel_m: 0", "max_texel_m: 0.001",
                           "neighbours: 0", "sigma_texels: 0", "grid: diagonal"}) {
    const core::ConfigDocument doc = core::ConfigDocument::fromString(yaml, "test.yaml");
    BitmapConfig config;
    EXPECT_THROW(readConfig(doc.root(), config), core::ConfigError) << yaml;
  }
  const core::ConfigDocument doc =
      core::ConfigDocument::fromString("texel_m: 0.004\ngrid: minimum_area", "test.yaml");
  BitmapConfig config;
  readConfig(doc.root(), config);
  EXPECT_EQ(config.texel_m, 0.004);
  EXPECT_EQ(config.grid, "minimum_area");
}

}  // namespace
}  // namespace tessera::texture
