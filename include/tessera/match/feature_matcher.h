#pragma once
// Feature matching for distinctive (non-periodic) textures: SIFT keypoints by default (ORB or
// AKAZE as options), nearest neighbours by FLANN (k-d trees for SIFT, LSH for the binary
// descriptors) with Lowe's ratio test, and a 2D similarity (rotation, uniform scale,
// translation) estimated by RANSAC over the surviving matches.
#include <optional>
#include <string>
#include <vector>

#include <opencv2/core/mat.hpp>
#include <opencv2/core/types.hpp>

#include "tessera/core/similarity2.h"

namespace tessera::match {

struct FeatureConfig {
  std::string detector = "sift";  // "sift", "orb" or "akaze"
  int max_features = 800;
  double ratio = 0.75;  // a match is kept when d1 < ratio d2
  double ransac_threshold_px = 3.0;
  int min_inliers = 12;
  double min_scale = 0.25, max_scale = 4.0;  // a similarity outside these is refused
};

struct Features {
  std::string kind;  // the detector that made them
  std::vector<cv::KeyPoint> keypoints;
  cv::Mat descriptors;  // one row per keypoint: CV_32F (SIFT) or CV_8U (ORB, AKAZE)
};

// Keypoints of an RGB bitmap (CV_8UC3) inside `mask` (CV_8UC1 non-zero = inside; empty: all),
// at most max_features of the strongest. Throws core::Error on an unknown detector name.
Features detectFeatures(const cv::Mat& rgb, const cv::Mat& mask, const FeatureConfig& config = {});

struct FeatureMatch {
  core::Similarity2 query_to_stored;  // query pixel (x, y) -> stored pixel
  int good_matches = 0;               // after the ratio test
  int inliers = 0;                    // of the RANSAC similarity
};

// The similarity from `query`'s pixels to `stored`'s, or nothing when fewer than min_inliers
// matches support one, the scale is out of bounds, or the kinds differ. Deterministic.
std::optional<FeatureMatch> matchFeatures(const Features& query, const Features& stored,
                                          const FeatureConfig& config = {});

}  // namespace tessera::match
