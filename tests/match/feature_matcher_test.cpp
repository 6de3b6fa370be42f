// Feature matching: a known similarity between a texture and its warped copy is recovered,
// unrelated textures are refused, and the answer does not change from call to call.
#include "tessera/match/feature_matcher.h"

#include <cmath>
#include <numbers>
#include <random>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "support/test_data.h"
#include "tessera/core/error.h"

namespace tessera::match {
namespace {

constexpr double kDegree = std::numbers::pi / 180.0;

// Random shapes of random colours over a blotchy background: corners and blobs at many scales.
cv::Mat texturedImage(int width, int height, unsigned seed) {
  std::mt19937 random(seed);
  std::uniform_int_distribution<int> colour(0, 255), x(0, width - 1), y(0, height - 1), size(3, 40);
  cv::Mat image(height, width, CV_8UC3);
  for (int r = 0; r < height; ++r) {
    for (int c = 0; c < width; ++c) {
      image.at<cv::Vec3b>(r, c) = cv::Vec3b(static_cast<std::uint8_t>(colour(random)),
                                            static_cast<std::uint8_t>(colour(random)),
                                            static_cast<std::uint8_t>(colour(random)));
    }
  }
  cv::GaussianBlur(image, image, cv::Size(), 4.0);
  for (int i = 0; i < 120; ++i) {
    const cv::Scalar c(colour(random), colour(random), colour(random));
    const cv::Point p(x(random), y(random));
    switch (i % 4) {
      case 0:
        cv::circle(image, p, size(random), c, cv::FILLED, cv::LINE_AA);
        break;
      case 1:
        cv::rectangle(image, p, p + cv::Point(size(random), size(random)), c, cv::FILLED);
        break;
      case 2: {
        const std::vector<cv::Point> triangle = {p, p + cv::Point(size(random), size(random) / 3),
                                                 p + cv::Point(size(random) / 4, size(random))};
        cv::fillConvexPoly(image, triangle, c, cv::LINE_AA);
        break;
      }
      default:
        cv::line(image, p, p + cv::Point(size(random) - 20, size(random) - 20), c, 3, cv::LINE_AA);
    }
  }
  return image;
}

struct Warped {
  cv::Mat rgb, mask;
};

// `image` seen through `s` (image pixel -> warped pixel) on a canvas of `size`; the mask marks
// where the image landed.
Warped warp(const cv::Mat& image, const core::Similarity2& s, cv::Size size) {
  const cv::Matx23d m(s.a, -s.b, s.tx, s.b, s.a, s.ty);
  Warped out;
  cv::warpAffine(image, out.rgb, m, size, cv::INTER_LINEAR, cv::BORDER_CONSTANT);
  cv::warpAffine(cv::Mat(image.size(), CV_8UC1, cv::Scalar(255)), out.mask, m, size,
                 cv::INTER_NEAREST, cv::BORDER_CONSTANT);
  return out;
}

void expectRecovered(const FeatureMatch& match, const core::Similarity2& truth, double max_deg,
                     double max_scale_error, cv::Point2d centre) {
  EXPECT_NEAR(match.query_to_stored.angleRad(), truth.angleRad(), max_deg * kDegree);
  EXPECT_NEAR(match.query_to_stored.scale() / truth.scale(), 1.0, max_scale_error);
  const Eigen::Vector2d c(centre.x, centre.y);
  EXPECT_LT((match.query_to_stored.apply(c) - truth.apply(c)).norm(), 2.0);
  EXPECT_GE(match.inliers, 12);
  EXPECT_LE(match.inliers, match.good_matches);
}

TEST(FeatureMatcher, SiftRecoversAKnownSimilarityAndDoesSoEveryTime) {
  const cv::Mat query = texturedImage(400, 300, 31);
  const auto truth = core::Similarity2::fromAngleScale(23.0 * kDegree, 1.15, 150.0, 10.0);
  const Warped stored = warp(query, truth, cv::Size(600, 520));

  const Features query_features = detectFeatures(query, {});
  const Features stored_features = detectFeatures(stored.rgb, stored.mask);
  const auto match = matchFeatures(query_features, stored_features);

  EXPECT_EQ(query_features.kind, "sift");
  EXPECT_EQ(query_features.descriptors.type(), CV_32F);
  EXPECT_LE(query_features.keypoints.size(), 800u);
  ASSERT_TRUE(match.has_value());
  expectRecovered(*match, truth, 1.0, 0.01, {200, 150});

  // Deterministic: the same answer again, whatever state the caller's generator is in.
  cv::theRNG() = cv::RNG(12345);
  const std::uint64_t caller_state = cv::theRNG().state;
  const auto again = matchFeatures(query_features, stored_features);
  EXPECT_EQ(cv::theRNG().state, caller_state);  // and that state is left alone
  ASSERT_TRUE(again.has_value());
  EXPECT_EQ(again->query_to_stored.a, match->query_to_stored.a);
  EXPECT_EQ(again->query_to_stored.b, match->query_to_stored.b);
  EXPECT_EQ(again->query_to_stored.tx, match->query_to_stored.tx);
  EXPECT_EQ(again->query_to_stored.ty, match->query_to_stored.ty);
  EXPECT_EQ(again->inliers, match->inliers);
  EXPECT_EQ(again->good_matches, match->good_matches);
}

TEST(FeatureMatcher, BinaryDescriptorsRecoverARotation) {
  const cv::Mat query = texturedImage(400, 300, 32);
  const auto truth = core::Similarity2::fromAngleScale(-40.0 * kDegree, 1.0, 40.0, 290.0);
  const Warped stored = warp(query, truth, cv::Size(560, 560));
  for (const char* detector : {"orb", "akaze"}) {
    SCOPED_TRACE(detector);
    FeatureConfig config;
    config.detector = detector;
    const Features q = detectFeatures(query, {}, config);
    const Features s = detectFeatures(stored.rgb, stored.mask, config);
    EXPECT_EQ(q.descriptors.type(), CV_8U);
    EXPECT_LE(s.keypoints.size(), 800u);
    const auto match = matchFeatures(q, s, config);
    ASSERT_TRUE(match.has_value());
    expectRecovered(*match, truth, 1.0, 0.02, {200, 150});
  }
}

TEST(FeatureMatcher, UnrelatedTexturesAreRefused) {
  const cv::Mat a = texturedImage(400, 300, 33), b = texturedImage(400, 300, 34);
  for (const char* detector : {"sift", "orb", "akaze"}) {
    SCOPED_TRACE(detector);
    FeatureConfig config;
    config.detector = detector;
    const Features fa = detectFeatures(a, {}, config), fb = detectFeatures(b, {}, config);
    ASSERT_GE(fa.keypoints.size(), 100u);  // refused for want of agreement, not of keypoints
    EXPECT_FALSE(matchFeatures(fa, fb, config).has_value());
  }
}

TEST(FeatureMatcher, KeypointsStayAwayFromTheMaskBorder) {
  const cv::Mat image = texturedImage(400, 300, 35);
  cv::Mat left(300, 400, CV_8UC1, cv::Scalar(0));
  left(cv::Rect(0, 0, 200, 300)).setTo(255);
  const Features features = detectFeatures(image, left);
  ASSERT_GT(features.keypoints.size(), 50u);
  for (const cv::KeyPoint& k : features.keypoints) EXPECT_LT(k.pt.x, 193.0F);
}

TEST(FeatureMatcher, NothingToMatchGivesNothingAndBadNamesThrow) {
  const cv::Mat flat(200, 200, CV_8UC3, cv::Scalar(90, 90, 90));
  const Features none = detectFeatures(flat, {});
  EXPECT_TRUE(none.keypoints.empty());
  const Features some = detectFeatures(texturedImage(200, 200, 36), {});
  EXPECT_FALSE(matchFeatures(none, some).has_value());
  EXPECT_FALSE(matchFeatures(some, none).has_value());
  FeatureConfig orb;
  orb.detector = "orb";
  EXPECT_FALSE(matchFeatures(some, detectFeatures(texturedImage(200, 200, 36), {}, orb)));
  FeatureConfig unknown;
  unknown.detector = "surf";
  EXPECT_THROW(detectFeatures(flat, {}, unknown), core::Error);
}

TEST(FeatureMatcher, SiftRecoversASimilarityOnARealPhoto) {
  TESSERA_REQUIRE_SHARED("textures/skimage_cc0");
  const cv::Mat grey = cv::imread((test::sharedData() / "textures/skimage_cc0/gravel.png").string(),
                                  cv::IMREAD_GRAYSCALE);
  ASSERT_FALSE(grey.empty());
  cv::Mat rgb;
  cv::cvtColor(grey, rgb, cv::COLOR_GRAY2RGB);
  const cv::Mat query = rgb(cv::Rect(100, 120, 300, 260)).clone();
  // The stored bitmap is the whole photo, rotated and shrunk: the query is a part of it.
  const auto truth_photo = core::Similarity2::fromAngleScale(-31.0 * kDegree, 0.9, 140.0, 330.0);
  const Warped stored = warp(rgb, truth_photo, cv::Size(720, 720));
  const auto crop_to_photo = core::Similarity2{1.0, 0.0, 100.0, 120.0};
  const auto truth = crop_to_photo.then(truth_photo);
  const auto match =
      matchFeatures(detectFeatures(query, {}), detectFeatures(stored.rgb, stored.mask));
  ASSERT_TRUE(match.has_value());
  expectRecovered(*match, truth, 1.0, 0.01, {150, 130});
}

}  // namespace
}  // namespace tessera::match
