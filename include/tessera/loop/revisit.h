#pragma once
// The geometric check of a revisit between two keyframes, and the weights of the pose graph's
// edges. A revisit is first posed from features (ORB, 3D-2D PnP in RANSAC, the tracker's
// method), then refined densely by point-to-plane ICP on the two depth images.
//
// Thread-safety: pure functions of their arguments.
#include <cstdint>
#include <optional>
#include <string>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "tessera/core/intrinsics.h"
#include "tessera/core/pose.h"
#include "tessera/fusion/feature_pose.h"
#include "tessera/loop/loop_config.h"

namespace tessera::loop {

using Matrix6d = Eigen::Matrix<double, 6, 6>;

// A keyframe as the loop closer keeps it.
struct KeyframeView {
  int id = -1;
  std::int64_t timestamp_ns = 0;
  core::Isometry T_W_C = core::Isometry::Identity();  // as tracked
  fusion::SharedFeatures features = std::make_shared<const fusion::FeatureFrame>();
  core::Intrinsics intrinsics;  // of the full frame (the features' pixels)
  cv::Mat depth_m;              // every dense_stride-th pixel, metres, NaN where missing
  double travel_m = 0.0;        // camera path length from the first keyframe, as tracked
  bool starts_segment = false;
  // A revisit of an older keyframe's place (LoopConfig::cover_radius_m): once it is no longer
  // needed, its features and depth are released and it is never a candidate.
  bool covered = false;
};

struct Revisit {
  core::Isometry T_query_match = core::Isometry::Identity();  // match camera -> query camera
  Matrix6d information = Matrix6d::Identity();
  int feature_inliers = 0;
  double fitness = 0.0;  // share of the match's points with a partner in the query's
  double rmse_m = 0.0;   // of those partners
};

// Keeps every `stride`-th pixel of `depth_m` (CV_32F, metres, NaN or 0 where missing).
cv::Mat strideDepth(const cv::Mat& depth_m, int stride);

// The pose of `query` relative to `match`, when features give one and dense ICP confirms it
// (fitness and rms within the config's bounds); else nullopt with `why` set.
std::optional<Revisit> verifyRevisit(const KeyframeView& match, const KeyframeView& query,
                                     const LoopConfig& config, std::string& why);

// The information matrix (6x6, rotation first, as Open3D's pose graph wants) of the motion
// T_target_source between two keyframes' depth point sets.
Matrix6d edgeInformation(const KeyframeView& source, const KeyframeView& target,
                         const core::Isometry& T_target_source, const LoopConfig& config);

}  // namespace tessera::loop
