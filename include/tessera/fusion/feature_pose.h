#pragma once
// Feature-based relative pose between two RGB-D frames, for motions too large for dense
// odometry (dropped frames, keyframe steps) and for relocalisation against a keyframe.
// Method: ORB keypoints with Lowe's ratio test on 2-NN Hamming matches; the reference
// keypoints' depths give 3D points, the current keypoints 2D points; PnP in RANSAC, then
// Levenberg-Marquardt on the inliers; the inliers' depths in the current frame must agree.
//
// Thread-safety: pure functions of their arguments; safe to call concurrently.
#include <memory>
#include <optional>
#include <vector>

#include <opencv2/core.hpp>

#include "tessera/core/config.h"
#include "tessera/core/intrinsics.h"
#include "tessera/core/pose.h"

namespace tessera::fusion {

struct FeaturePoseConfig {
  int max_features = 1000;  // ORB keypoints per frame
  double ratio_test = 0.8;  // best match kept if its distance < ratio_test * second best
  int min_inliers = 25;     // fewer PnP inliers: no pose
  double ransac_reprojection_px = 3.0;  // PnP inlier threshold, pixels
  int ransac_iterations = 300;
  // Keypoints outside [min, max] depth have no 3D point. Far points (Kinect v1 walls at 6-8 m)
  // still fix the rotation: with a 6 m limit three of the four dining-room pairs found no pose,
  // with 4 m none did.
  double min_depth_m = 0.3;
  double max_depth_m = 10.0;
  // Depths that should be equal may differ by this fraction: a keypoint whose 4 neighbours
  // differ more is on a depth edge (no 3D point); an inlier whose depth in the current frame
  // differs more from the pose's prediction is dropped. Real Kinect v1 depth at 7 m was 7-9%
  // off between views.
  double depth_tolerance_fraction = 0.1;
  // A pose is refused when fewer of the inliers with current depth than this agree.
  double min_depth_agreement = 0.6;
  // Poses whose standard deviation (from the inliers' geometry and reprojection error) exceeds
  // these are refused: inliers that are few, clustered or collinear do not fix the pose.
  double max_translation_sigma_m = 0.03;
  double max_rotation_sigma_deg = 1.0;
};

// Overwrites the members present in `section`; throws core::ConfigError on a bad value.
void readConfig(const core::ConfigSection& section, FeaturePoseConfig& config);

// One frame's keypoints with their descriptors and depths.
struct FeatureFrame {
  std::vector<cv::KeyPoint> keypoints;
  cv::Mat descriptors;  // CV_8U, one 32-byte ORB row per keypoint
  // Per keypoint, its point in this camera's coordinates (metres); NaN where the depth at the
  // keypoint is missing, outside the depth range, or on a depth edge.
  std::vector<cv::Point3f> points_C;
};

// A keyframe's features as its holders share them (the tracker, loop closure and the saved
// map each keep every keyframe: about 70 KB of features each, which copies would triple).
using SharedFeatures = std::shared_ptr<const FeatureFrame>;

// Describes a frame as the tracker holds it: `grey` CV_8UC1 (colour registered to depth),
// `depth_m` CV_32FC1 in metres with NaN (or 0) where invalid, both at the size of `k`.
// Empty images give a FeatureFrame without keypoints. Throws core::Error when the types or
// sizes disagree (a programming error, not a bad frame).
FeatureFrame describeFeatures(const cv::Mat& grey, const cv::Mat& depth_m,
                              const core::Intrinsics& k, const FeaturePoseConfig& config);

struct FeaturePose {
  core::Isometry T_current_reference = core::Isometry::Identity();  // reference -> current
  int inliers = 0;  // matches within the reprojection threshold whose current depth agrees
  int matches = 0;  // ratio-test matches with a reference 3D point
  double reprojection_rms_px = 0.0;  // over the inliers
  // Largest standard deviations of the translation and rotation, from the reprojection rms and
  // the inliers' geometry (Gauss-Newton covariance); depth noise is not included.
  double translation_sigma_m = 0.0;
  double rotation_sigma_deg = 0.0;
};

// The pose of `current` relative to `reference`, or nullopt when there are too few features,
// matches or inliers, the current depth contradicts the pose, or the pose is too uncertain
// (max_translation_sigma_m, max_rotation_sigma_deg). Never throws on bad frames.
// Intrinsics with a negative fy (image y axis flipped) are handled.
std::optional<FeaturePose> estimateFeaturePose(const FeatureFrame& reference,
                                               const FeatureFrame& current,
                                               const core::Intrinsics& k,
                                               const FeaturePoseConfig& config);

}  // namespace tessera::fusion
