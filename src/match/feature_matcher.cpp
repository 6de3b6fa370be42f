#include "tessera/match/feature_matcher.h"

#include <algorithm>
#include <numeric>
#include <optional>

#include <fmt/format.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/features2d.hpp>
#include <opencv2/flann.hpp>
#include <opencv2/imgproc.hpp>

#include "internal/seeded_rng.h"
#include "tessera/core/error.h"

namespace tessera::match {
namespace {

constexpr std::uint64_t kMatcherSeed = 0x5eed;  // any fixed value: reproducible FLANN

// Keypoints closer than this to the mask border are dropped: their descriptors would see what
// lies outside the patch, which differs between two sightings of the same texture.
constexpr int kMaskMarginPx = 8;
constexpr int kRansacIterations = 5000;
constexpr int kRepeatedRansacIterations = 4000;
constexpr double kRansacConfidence = 0.999;
constexpr int kKdTrees = 4;
constexpr int kMatcherChecks = 64;
constexpr double kClaheClipLimit = 3.0;
constexpr int kClaheTiles = 8;

using internal::SeededRng;

cv::Ptr<cv::Feature2D> makeDetector(const FeatureConfig& config) {
  if (config.detector == "sift") return cv::SIFT::create(config.max_features);
  if (config.detector == "orb") return cv::ORB::create(config.max_features);
  if (config.detector == "akaze") return cv::AKAZE::create();  // no feature budget: trimmed later
  throw core::Error(
      fmt::format("unknown feature detector '{}' (known: sift, orb, akaze)", config.detector));
}

cv::Mat detectionMask(const cv::Mat& rgb, const cv::Mat& mask) {
  if (mask.empty()) return {};
  if (mask.type() != CV_8UC1 || mask.size() != rgb.size()) {
    throw core::Error("detectFeatures: the mask must be CV_8UC1 of the image's size");
  }
  cv::Mat inside, eroded;
  cv::compare(mask, 0, inside, cv::CMP_NE);
  const cv::Mat disc = cv::getStructuringElement(
      cv::MORPH_ELLIPSE, cv::Size(2 * kMaskMarginPx + 1, 2 * kMaskMarginPx + 1));
  // Outside the image counts as outside the mask too.
  cv::erode(inside, eroded, disc, cv::Point(-1, -1), 1, cv::BORDER_CONSTANT, cv::Scalar(0));
  return eroded;
}

// The `count` strongest keypoints and their descriptor rows (ties: detection order).
void keepStrongest(Features& features, int count) {
  if (count < 0 || features.keypoints.size() <= static_cast<std::size_t>(count)) return;
  std::vector<int> order(features.keypoints.size());
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) {
    return features.keypoints[static_cast<std::size_t>(a)].response >
           features.keypoints[static_cast<std::size_t>(b)].response;
  });
  order.resize(static_cast<std::size_t>(count));
  Features kept{features.kind, {}, {}};
  for (const int i : order) {
    kept.keypoints.push_back(features.keypoints[static_cast<std::size_t>(i)]);
    kept.descriptors.push_back(features.descriptors.row(i));
  }
  features = std::move(kept);
}

// Grey levels with their local contrast equalised (CLAHE): wood grain, plaster and other
// low-contrast surfaces give keypoints too, and two exposures of one surface look alike.
// Texels outside the mask take the mean grey inside it first, so that the empty border does
// not set the contrast of the tiles it touches.
cv::Mat equalisedGrey(const cv::Mat& rgb, const cv::Mat& mask) {
  cv::Mat grey;
  cv::cvtColor(rgb, grey, cv::COLOR_RGB2GRAY);
  if (!mask.empty()) {
    const cv::Scalar mean = cv::mean(grey, mask);
    cv::Mat outside;
    cv::compare(mask, 0, outside, cv::CMP_EQ);
    grey.setTo(mean, outside);
  }
  cv::Mat equalised;
  cv::createCLAHE(kClaheClipLimit, cv::Size(kClaheTiles, kClaheTiles))->apply(grey, equalised);
  return equalised;
}

// The RANSAC similarity over the nearest-neighbour matches that pass the ratio test (1: all).
std::optional<FeatureMatch> similarityFrom(const Features& query, const Features& stored,
                                           const std::vector<std::vector<cv::DMatch>>& nearest,
                                           double ratio, const FeatureConfig& config,
                                           int iterations) {
  std::vector<cv::Point2f> from, to;
  for (const auto& pair : nearest) {
    if (pair.empty()) continue;
    if (ratio < 1.0 && (pair.size() < 2 || pair[0].distance >= ratio * pair[1].distance)) continue;
    from.push_back(query.keypoints[static_cast<std::size_t>(pair[0].queryIdx)].pt);
    to.push_back(stored.keypoints[static_cast<std::size_t>(pair[0].trainIdx)].pt);
  }
  const int min_inliers = std::max(config.min_inliers, 2);  // a similarity needs two points
  const int good = static_cast<int>(from.size());
  if (good < min_inliers) return std::nullopt;
  std::vector<std::uint8_t> inlier_flags;
  // OpenCV's RANSAC here draws from a fixed-seed generator: the answer is reproducible.
  const cv::Mat m =
      cv::estimateAffinePartial2D(from, to, inlier_flags, cv::RANSAC, config.ransac_threshold_px,
                                  static_cast<std::size_t>(iterations), kRansacConfidence);
  if (m.empty()) return std::nullopt;
  const int inliers = cv::countNonZero(inlier_flags);
  const core::Similarity2 query_to_stored{m.at<double>(0, 0), m.at<double>(1, 0),
                                          m.at<double>(0, 2), m.at<double>(1, 2)};
  const double scale = query_to_stored.scale();
  if (inliers < min_inliers || scale < config.min_scale || scale > config.max_scale) {
    return std::nullopt;
  }
  return FeatureMatch{query_to_stored, good, inliers};
}

cv::Ptr<cv::DescriptorMatcher> makeMatcher(int descriptor_type) {
  const auto search = cv::makePtr<cv::flann::SearchParams>(kMatcherChecks);
  if (descriptor_type == CV_32F) {
    return cv::makePtr<cv::FlannBasedMatcher>(cv::makePtr<cv::flann::KDTreeIndexParams>(kKdTrees),
                                              search);
  }
  // Binary descriptors: locality-sensitive hashing, 6 tables of 12-bit keys, probing neighbours.
  return cv::makePtr<cv::FlannBasedMatcher>(cv::makePtr<cv::flann::LshIndexParams>(6, 12, 1),
                                            search);
}

}  // namespace

Features detectFeatures(const cv::Mat& rgb, const cv::Mat& mask, const FeatureConfig& config) {
  const cv::Ptr<cv::Feature2D> detector = makeDetector(config);
  if (rgb.empty() || rgb.type() != CV_8UC3) {
    throw core::Error("detectFeatures: the image must be a non-empty CV_8UC3");
  }
  const cv::Mat grey = equalisedGrey(rgb, mask);
  Features features;
  features.kind = config.detector;
  detector->detectAndCompute(grey, detectionMask(rgb, mask), features.keypoints,
                             features.descriptors);
  keepStrongest(features, config.max_features);
  return features;
}

std::optional<FeatureMatch> matchFeatures(const Features& query, const Features& stored,
                                          const FeatureConfig& config) {
  for (const Features* f : {&query, &stored}) {
    if (static_cast<std::size_t>(f->descriptors.rows) != f->keypoints.size()) {
      throw core::Error("matchFeatures: descriptor rows and keypoints differ in number");
    }
  }
  if (query.kind != stored.kind || query.descriptors.type() != stored.descriptors.type()) {
    return std::nullopt;
  }
  const int min_inliers = std::max(config.min_inliers, 2);  // a similarity needs two points
  if (query.descriptors.rows < min_inliers || stored.descriptors.rows < 2) return std::nullopt;

  std::vector<std::vector<cv::DMatch>> nearest;
  {
    SeededRng seeded(kMatcherSeed);
    makeMatcher(query.descriptors.type())
        ->knnMatch(query.descriptors, stored.descriptors, nearest, 2);
  }
  // Lowe's ratio test: keep a match only when clearly nearer than the runner-up.
  std::optional<FeatureMatch> found =
      similarityFrom(query, stored, nearest, config.ratio, config, kRansacIterations);
  if (found) return found;
  // A repeating texture (bricks, tiles) has no clear runner-up: every feature has twins one
  // period away. Then every nearest neighbour is kept, and RANSAC (given more draws, as fewer
  // matches agree) looks for the shift most of them share; any lattice shift reproduces the
  // texture, and the cascade's fidelity check judges the result.
  return similarityFrom(query, stored, nearest, 1.0, config, kRepeatedRansacIterations);
}

}  // namespace tessera::match
