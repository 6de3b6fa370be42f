// View selection, alignment and seam levelling on samples with known truth: views with known
// jitter, gains and occlusion.
#include <cmath>
#include <filesystem>
#include <random>

#include <gtest/gtest.h>

#include <opencv2/core.hpp>

#include "tessera/texture/bitmap_builder.h"

namespace tessera::texture {
namespace {

using planes::ColourSample;

constexpr double kSide = 0.24;    // metres: a square patch
constexpr double kTexel = 0.005;  // metres
constexpr double kPixel = 0.004;  // a view's pixel footprint on the plane

planes::PatchSnapshot squareOfViews() {
  planes::PatchSnapshot patch;
  patch.id = 3;
  patch.version = 1;
  patch.outline.parts.push_back({{{0, 0}, {kSide, 0}, {kSide, kSide}, {0, kSide}}, {}});
  return patch;
}

// Grey detail of about a centimetre, not periodic within the alignment's reach.
double detailAt(double u, double v) {
  constexpr double kTwoPi = 6.283185307179586;
  return 128.0 + 45.0 * std::sin(kTwoPi * u / 0.041 + 0.3) + 35.0 * std::sin(kTwoPi * v / 0.033) +
         25.0 * std::sin(kTwoPi * (u + v) / 0.027);
}

struct ViewSpec {
  std::int32_t id = 0;
  Eigen::Vector2d jitter = Eigen::Vector2d::Zero();  // where its samples land minus the truth
  double gain = 1.0;
  float score = 0.0F;
  double row_step = kPixel;  // wider: the rows of a view at a grazing angle
  // Part of the plane the view sees (u0, v0, u1, v1), and an occluded box within it.
  cv::Vec4d sees{0, 0, kSide, kSide};
  cv::Vec4d hidden{-1, -1, -1, -1};
};

bool within(const cv::Vec4d& box, double u, double v) {
  return u >= box[0] && v >= box[1] && u < box[2] && v < box[3];
}

// One view's pixels on the plane: a lattice at its footprint with a random sub-pixel phase,
// coloured by `truth` times its gain, with noise.
template <typename Truth>
void addView(planes::PatchSnapshot& patch, const ViewSpec& view, Truth truth,
             std::mt19937& random) {
  std::uniform_real_distribution<double> phase(0.0, kPixel);
  std::normal_distribution<double> noise(0.0, 1.5);
  const double u0 = phase(random), v0 = phase(random);
  for (double v = v0; v < kSide; v += view.row_step) {
    for (double u = u0; u < kSide; u += kPixel) {
      if (!within(view.sees, u, v) || within(view.hidden, u, v)) continue;
      const cv::Vec3d colour = truth(u, v);
      ColourSample s;
      s.u = static_cast<float>(u + view.jitter.x());
      s.v = static_cast<float>(v + view.jitter.y());
      for (int c = 0; c < 3; ++c) {
        s.rgb[static_cast<std::size_t>(c)] =
            cv::saturate_cast<std::uint8_t>(view.gain * colour[c] + noise(random));
      }
      s.score = view.score;
      s.view = view.id;
      patch.samples.push_back(s);
    }
  }
}

cv::Vec3d greyDetail(double u, double v) {
  const double g = detailAt(u, v);
  return {g, g, g};
}

BitmapConfig viewConfig() {
  BitmapConfig config;
  config.texel_m = kTexel;
  config.max_inpaint_texels = 0;
  return config;
}

// PSNR of a bitmap against the truth at its texel centres, away from the outline's edge.
template <typename Truth>
double psnrAgainst(const PatchBitmap& bitmap, Truth truth) {
  double squared = 0.0, count = 0.0;
  constexpr int kMargin = 4;
  for (int r = kMargin; r < bitmap.grid.height - kMargin; ++r) {
    for (int c = kMargin; c < bitmap.grid.width - kMargin; ++c) {
      if (bitmap.state.at<std::uint8_t>(r, c) == 0) continue;
      const Eigen::Vector2d uv = bitmap.grid.uvOf(c + 0.5, r + 0.5);
      const cv::Vec3d want = truth(uv.x(), uv.y());
      const cv::Vec3b got = bitmap.image.at<cv::Vec3b>(r, c);
      for (int ch = 0; ch < 3; ++ch) squared += std::pow(got[ch] - want[ch], 2);
      count += 3.0;
    }
  }
  return 10.0 * std::log10(255.0 * 255.0 / (squared / std::max(count, 1.0)));
}

TEST(ViewSelection, LabellingKeepsOneViewUnlessAViewIsMuchBetter) {
  // A strip of regions whose best view alternates, each only 10 % ahead of the other.
  std::vector<RegionViews> strip(8);
  for (std::size_t i = 0; i < strip.size(); ++i) {
    const std::int32_t best = static_cast<std::int32_t>(i % 2), other = 1 - best;
    strip[i] = {{best, other}, {1.0, 0.9}};
  }
  const std::vector<int> smooth = labelRegions(strip, 8, 1, 0.25);
  const std::vector<int> greedy = labelRegions(strip, 8, 1, 0.0);
  for (std::size_t i = 0; i < strip.size(); ++i) {
    EXPECT_EQ(strip[i].views[static_cast<std::size_t>(smooth[i])],
              strip[0].views[static_cast<std::size_t>(smooth[0])]);
    EXPECT_EQ(greedy[i], 0);  // without the seam cost each region takes its own best
  }
  // A region whose other views are 20 times lighter keeps its own view despite two seams.
  strip[3] = {{7, 0, 1}, {20.0, 1.0, 1.0}};
  const std::vector<int> labels = labelRegions(strip, 8, 1, 0.25);
  EXPECT_EQ(strip[3].views[static_cast<std::size_t>(labels[3])], 7);
}

TEST(ViewSelection, AJitteredSequenceStaysWithinOneDbOfTheJitterFreeOne) {
  // Six views, each misregistered by up to 7 mm (zero mean), against the same views exact.
  std::mt19937 random(11);
  std::uniform_real_distribution<double> offset(-0.007, 0.007);
  std::vector<Eigen::Vector2d> jitters(6);
  Eigen::Vector2d mean = Eigen::Vector2d::Zero();
  for (auto& jitter : jitters) mean += (jitter = {offset(random), offset(random)}) / 6.0;
  planes::PatchSnapshot exact = squareOfViews(), jittered = squareOfViews();
  for (std::size_t k = 0; k < jitters.size(); ++k) {
    ViewSpec view;
    view.id = static_cast<std::int32_t>(k);
    view.score = -0.1F * static_cast<float>(k);
    std::mt19937 same_pixels(100 + static_cast<std::uint32_t>(k));
    addView(exact, view, greyDetail, same_pixels);
    view.jitter = jitters[k] - mean;
    same_pixels.seed(100 + static_cast<std::uint32_t>(k));
    addView(jittered, view, greyDetail, same_pixels);
  }
  const BitmapConfig config = viewConfig();
  const double reference = psnrAgainst(buildBitmap(exact, config), greyDetail);
  const PatchBitmap aligned = buildBitmap(jittered, config);
  const double selected = psnrAgainst(aligned, greyDetail);
  BitmapConfig plain = config;
  plain.views.enabled = false;
  plain.alignment.enabled = false;
  const double mean_of_views = psnrAgainst(buildBitmap(jittered, plain), greyDetail);
  EXPECT_GT(reference, 30.0);
  EXPECT_GT(selected, reference - 1.0);
  EXPECT_LT(mean_of_views, selected - 3.0);  // the plain mean smears the detail
  EXPECT_GE(aligned.views_moved, 4);
  EXPECT_LT(aligned.view_shift_max_mm, 16.0);  // the jitter is at most 14 mm
}

TEST(ViewSelection, AnOccludedViewIsNeverTaken) {
  // The heavier view is red and blocked over a 6 x 6 cm box; the lighter one is blue.
  planes::PatchSnapshot patch = squareOfViews();
  std::mt19937 random(5);
  ViewSpec red;
  red.id = 1;
  red.hidden = {0.09, 0.09, 0.15, 0.15};
  addView(
      patch, red, [](double, double) { return cv::Vec3d(200, 40, 40); }, random);
  ViewSpec blue;
  blue.id = 2;
  blue.score = -1.0F;
  addView(
      patch, blue, [](double, double) { return cv::Vec3d(40, 40, 200); }, random);
  const BitmapConfig config = viewConfig();
  const PatchBitmap bitmap = buildBitmap(patch, config);
  // Texels further inside the box than the reach of a sample outside it (radius_texels).
  const double reach = config.radius_texels * kTexel;
  const cv::Vec4d deep(red.hidden[0] + reach, red.hidden[1] + reach, red.hidden[2] - reach,
                       red.hidden[3] - reach);
  int hidden = 0;
  for (int r = 0; r < bitmap.grid.height; ++r) {
    for (int c = 0; c < bitmap.grid.width; ++c) {
      const Eigen::Vector2d uv = bitmap.grid.uvOf(c + 0.5, r + 0.5);
      if (!within(deep, uv.x(), uv.y())) continue;
      ASSERT_NE(bitmap.state.at<std::uint8_t>(r, c), 0);
      const cv::Vec3b colour = bitmap.image.at<cv::Vec3b>(r, c);
      EXPECT_GT(colour[2], colour[0]) << "texel " << c << ", " << r;
      ++hidden;
    }
  }
  EXPECT_GT(hidden, 64);
}

TEST(ViewSelection, SeamLevellingRemovesAViewsGainButKeepsTheShading) {
  // A grey ramp (shading, 60 to 180 across the patch) with fine detail, seen by two views
  // that overlap in the middle; the right one is 30 % brighter.
  const auto shaded = [](double u, double v) {
    const double g = 60.0 + 120.0 * u / kSide + 0.15 * (detailAt(u, v) - 128.0);
    return cv::Vec3d(g, g, g);
  };
  planes::PatchSnapshot patch = squareOfViews();
  std::mt19937 random(9);
  ViewSpec left;
  left.id = 1;
  left.sees = {0, 0, 0.6 * kSide, kSide};
  addView(patch, left, shaded, random);
  ViewSpec right;
  right.id = 2;
  right.gain = 1.3;
  right.sees = {0.4 * kSide, 0, kSide, kSide};
  addView(patch, right, shaded, random);
  BitmapConfig config = viewConfig();
  BitmapConfig unlevelled = config;
  unlevelled.views.level_seams = false;
  const PatchBitmap levelled = buildBitmap(patch, config);
  const PatchBitmap raw = buildBitmap(patch, unlevelled);
  ASSERT_GT(levelled.seams, 0);
  EXPECT_GT(levelled.seam_step, 15.0);
  EXPECT_LT(levelled.seam_step_levelled, 0.25 * levelled.seam_step);
  // Mean green per texel-wide band of u (the ramp's direction): no step left where the views
  // meet, and the ramp is kept.
  const auto bandMeans = [](const PatchBitmap& bitmap) {
    const int bands = static_cast<int>(kSide / kTexel);
    std::vector<double> sum(static_cast<std::size_t>(bands), 0.0), n(sum.size(), 0.0);
    for (int r = 0; r < bitmap.grid.height; ++r) {
      for (int c = 0; c < bitmap.grid.width; ++c) {
        const Eigen::Vector2d uv = bitmap.grid.uvOf(c + 0.5, r + 0.5);
        const int band = static_cast<int>(uv.x() / kTexel);
        if (bitmap.state.at<std::uint8_t>(r, c) == 0 || band < 0 || band >= bands) continue;
        sum[static_cast<std::size_t>(band)] += bitmap.image.at<cv::Vec3b>(r, c)[1];
        n[static_cast<std::size_t>(band)] += 1.0;
      }
    }
    for (std::size_t k = 0; k < sum.size(); ++k) sum[k] /= std::max(n[k], 1.0);
    return sum;
  };
  const std::vector<double> level = bandMeans(levelled), unlevel = bandMeans(raw);
  double largest_step = 0.0, raw_step = 0.0;
  for (std::size_t k = 4; k + 8 < level.size(); ++k) {
    // Over 4 texels the ramp climbs 10 levels; the gain step adds about 40.
    largest_step = std::max(largest_step, std::abs(level[k + 4] - level[k]));
    raw_step = std::max(raw_step, std::abs(unlevel[k + 4] - unlevel[k]));
  }
  EXPECT_GT(raw_step, 30.0);
  EXPECT_LT(largest_step, 0.7 * raw_step);
  const double ramp = level[level.size() - 5] - level[4];
  const auto bands = static_cast<double>(level.size());
  EXPECT_GT(ramp, 0.8 * 120.0 * (bands - 9.0) / bands);
}

TEST(ViewSelection, AGrazingViewLeavesNoCombOfEmptyRows) {
  // The only view sees the plane at a grazing angle: its rows land 3.5 texels apart.
  planes::PatchSnapshot patch = squareOfViews();
  std::mt19937 random(2);
  ViewSpec grazing;
  grazing.id = 4;
  grazing.row_step = 3.5 * kTexel;
  addView(patch, grazing, greyDetail, random);
  const PatchBitmap bitmap = buildBitmap(patch, viewConfig());
  BitmapConfig plain = viewConfig();
  plain.views.enabled = false;
  const PatchBitmap mean = buildBitmap(patch, plain);
  const cv::Rect inner(4, 4, bitmap.grid.width - 8, bitmap.grid.height - 8);
  EXPECT_EQ(cv::countNonZero(bitmap.state(inner)), inner.area());
  EXPECT_LT(cv::countNonZero(mean.state(inner)), inner.area());  // the mean's comb
}

TEST(ColourSamples, EachTileKeepsItsHeaviestViewsApart) {
  planes::ColourSamples samples(0.01, 2);
  const std::array<float, 4> weights = {1.0F, 5.0F, 3.0F, 0.5F};
  for (std::int32_t view = 0; view < 4; ++view) {
    for (int i = 0; i < 10; ++i) {
      samples.add(0.005F + 0.01F * static_cast<float>(i), 0.005F,
                  {static_cast<std::uint8_t>(50 * view), 0, 0},
                  weights[static_cast<std::size_t>(view)], view);
    }
    samples.settle();
  }
  const std::vector<ColourSample> all = samples.all();
  ASSERT_EQ(all.size(), 20u);
  EXPECT_EQ(samples.size(), 20u);
  for (const ColourSample& s : all) {
    EXPECT_TRUE(s.view == 1 || s.view == 2);
    EXPECT_EQ(s.rgb[0], 50 * s.view);  // a view's cells hold its colour only
  }
  // The heaviest view answers colourAt.
  EXPECT_NEAR((*samples.colourAt(0.005F, 0.005F))[0], 50.0F, 0.5F);
  const auto file = std::filesystem::temp_directory_path() / "tessera_view_layers.samples";
  samples.save(file);
  const planes::ColourSamples back = planes::ColourSamples::load(file);
  std::filesystem::remove(file);
  EXPECT_EQ(back.size(), samples.size());
  EXPECT_EQ(back.all().size(), all.size());
  EXPECT_EQ(back.bytes(), samples.bytes());
}

}  // namespace
}  // namespace tessera::texture
