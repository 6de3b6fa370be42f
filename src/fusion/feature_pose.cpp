#include "tessera/fusion/feature_pose.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <Eigen/Eigenvalues>

#include <fmt/format.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/core/eigen.hpp>
#include <opencv2/features2d.hpp>

#include "tessera/core/error.h"

namespace tessera::fusion {

void readConfig(const core::ConfigSection& section, FeaturePoseConfig& config) {
  section.read("max_features", config.max_features);
  section.read("ratio_test", config.ratio_test);
  section.read("min_inliers", config.min_inliers);
  section.read("ransac_reprojection_px", config.ransac_reprojection_px);
  section.read("ransac_iterations", config.ransac_iterations);
  section.read("min_depth_m", config.min_depth_m);
  section.read("max_depth_m", config.max_depth_m);
  section.read("depth_tolerance_fraction", config.depth_tolerance_fraction);
  section.read("min_depth_agreement", config.min_depth_agreement);
  section.read("max_translation_sigma_m", config.max_translation_sigma_m);
  section.read("max_rotation_sigma_deg", config.max_rotation_sigma_deg);
  if (config.max_features < 10 || config.min_inliers < 6 || config.ransac_iterations < 1) {
    throw core::ConfigError(
        "feature_pose: need max_features >= 10, min_inliers >= 6 (PnP needs a margin over its "
        "minimum) and ransac_iterations >= 1");
  }
  if (!(config.ratio_test > 0.0 && config.ratio_test <= 1.0) ||
      !(config.ransac_reprojection_px > 0.0) || !(config.min_depth_m > 0.0) ||
      !(config.max_depth_m > config.min_depth_m) || !(config.depth_tolerance_fraction > 0.0) ||
      !(config.min_depth_agreement >= 0.0 && config.min_depth_agreement <= 1.0) ||
      !(config.max_translation_sigma_m > 0.0) || !(config.max_rotation_sigma_deg > 0.0)) {
    throw core::ConfigError(
        "feature_pose: need 0 < ratio_test <= 1, ransac_reprojection_px > 0, "
        "0 < min_depth_m < max_depth_m, depth_tolerance_fraction > 0, "
        "min_depth_agreement in [0, 1] and positive sigma bounds");
  }
}

namespace {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
// Keypoint selection: ORB detects this many times max_features, then a grid of this many cells
// spreads the kept ones (measured on the synthetic office and the Kinect dining room: 4 x 3
// found more poses than 8 x 6 or 16 x 12, at the same accuracy).
constexpr int kDetectionOversampling = 4;
constexpr int kGridCols = 4;
constexpr int kGridRows = 3;

bool finite(const cv::Point3f& p) { return std::isfinite(p.z); }

// The depth at pixel (u, v), or NaN when it or a 4-neighbour is missing or differs by more
// than `edge_fraction` of it: a keypoint on a depth edge could belong to either side.
float depthAt(const cv::Mat& depth_m, int u, int v, float edge_fraction) {
  if (u < 1 || v < 1 || u >= depth_m.cols - 1 || v >= depth_m.rows - 1) return kNaN;
  const float z = depth_m.at<float>(v, u);
  if (!(z > 0.0f)) return kNaN;
  const float around[4] = {depth_m.at<float>(v - 1, u), depth_m.at<float>(v + 1, u),
                           depth_m.at<float>(v, u - 1), depth_m.at<float>(v, u + 1)};
  for (const float n : around) {
    if (!(std::abs(n - z) <= edge_fraction * z)) return kNaN;  // also NaN neighbours
  }
  return z;
}

}  // namespace

FeatureFrame describeFeatures(const cv::Mat& grey, const cv::Mat& depth_m,
                              const core::Intrinsics& k, const FeaturePoseConfig& config) {
  FeatureFrame frame;
  if (grey.empty() || depth_m.empty()) return frame;
  if (grey.type() != CV_8UC1 || depth_m.type() != CV_32FC1 || grey.size() != depth_m.size() ||
      grey.cols != k.width || grey.rows != k.height) {
    throw core::Error(fmt::format(
        "describeFeatures: need CV_8UC1 grey and CV_32FC1 depth in metres at the intrinsics' "
        "size {}x{}; got types {} and {} at {}x{} and {}x{}",
        k.width, k.height, grey.type(), depth_m.type(), grey.cols, grey.rows, depth_m.cols,
        depth_m.rows));
  }
  if (k.fx == 0.0 || k.fy == 0.0) return frame;

  // ORB keeps the strongest corners, which crowd onto the most contrasted objects; PnP needs
  // them spread over the view. So detect more, and take them round robin from the cells of a
  // grid, strongest first in each cell (an empty cell's share goes to the textured ones).
  cv::Ptr<cv::ORB> orb = cv::ORB::create(config.max_features * kDetectionOversampling);
  std::vector<cv::KeyPoint> detected;
  orb->detect(grey, detected);
  std::vector<std::vector<cv::KeyPoint>> cells(kGridCols * kGridRows);
  for (const cv::KeyPoint& kp : detected) {
    const int col = std::clamp(static_cast<int>(kp.pt.x) * kGridCols / grey.cols, 0, kGridCols - 1);
    const int row = std::clamp(static_cast<int>(kp.pt.y) * kGridRows / grey.rows, 0, kGridRows - 1);
    cells[static_cast<std::size_t>(row * kGridCols + col)].push_back(kp);
  }
  for (auto& cell : cells) {
    std::sort(cell.begin(), cell.end(),
              [](const cv::KeyPoint& a, const cv::KeyPoint& b) { return a.response > b.response; });
  }
  const auto budget = static_cast<std::size_t>(config.max_features);
  for (std::size_t rank = 0, taken = 1; taken > 0 && frame.keypoints.size() < budget; ++rank) {
    taken = 0;
    for (const auto& cell : cells) {
      if (rank >= cell.size() || frame.keypoints.size() >= budget) continue;
      frame.keypoints.push_back(cell[rank]);
      ++taken;
    }
  }
  orb->compute(grey, frame.keypoints, frame.descriptors);
  frame.points_C.reserve(frame.keypoints.size());
  const auto edge_fraction = static_cast<float>(config.depth_tolerance_fraction);
  for (const cv::KeyPoint& kp : frame.keypoints) {
    const int u = cvRound(kp.pt.x);
    const int v = cvRound(kp.pt.y);
    const float z = depthAt(depth_m, u, v, edge_fraction);
    if (!(z >= config.min_depth_m && z <= config.max_depth_m)) {
      frame.points_C.emplace_back(kNaN, kNaN, kNaN);
      continue;
    }
    // The keypoint's sub-pixel position on the depth of its pixel.
    frame.points_C.emplace_back(static_cast<float>((kp.pt.x - k.cx) / k.fx * z),
                                static_cast<float>((kp.pt.y - k.cy) / k.fy * z), z);
  }
  return frame;
}

namespace {

// estimateFeaturePose without its guard against OpenCV exceptions.
std::optional<FeaturePose> estimate(const FeatureFrame& reference, const FeatureFrame& current,
                                    const core::Intrinsics& k, const FeaturePoseConfig& config) {
  if (k.fx == 0.0 || k.fy == 0.0) return std::nullopt;
  if (reference.keypoints.size() < static_cast<std::size_t>(config.min_inliers) ||
      current.keypoints.size() < static_cast<std::size_t>(config.min_inliers) ||
      reference.descriptors.rows != static_cast<int>(reference.keypoints.size()) ||
      current.descriptors.rows != static_cast<int>(current.keypoints.size())) {
    return std::nullopt;
  }

  // Current keypoints (queries) to reference ones; Lowe's ratio test, then each reference
  // keypoint keeps only its best match.
  std::vector<std::vector<cv::DMatch>> knn;
  cv::BFMatcher(cv::NORM_HAMMING).knnMatch(current.descriptors, reference.descriptors, knn, 2);
  std::vector<cv::DMatch> best_for_reference(reference.keypoints.size(),
                                             cv::DMatch(-1, -1, std::numeric_limits<float>::max()));
  for (const auto& pair : knn) {
    if (pair.size() < 2 || pair[0].distance >= config.ratio_test * pair[1].distance) continue;
    const cv::DMatch& m = pair[0];
    if (!finite(reference.points_C[static_cast<std::size_t>(m.trainIdx)])) continue;
    cv::DMatch& best = best_for_reference[static_cast<std::size_t>(m.trainIdx)];
    if (m.distance < best.distance) best = m;
  }

  // A negative focal length flips an image axis; PnP wants positive ones, so it works in
  // coordinates with that axis flipped (F = diag(sx, sy, 1)) and the pose is flipped back.
  const float sx = k.fx < 0.0 ? -1.0f : 1.0f;
  const float sy = k.fy < 0.0 ? -1.0f : 1.0f;
  std::vector<cv::Point3f> object;  // F * reference point
  std::vector<cv::Point2f> image;   // current keypoint
  std::vector<int> current_index;
  for (const cv::DMatch& m : best_for_reference) {
    if (m.queryIdx < 0) continue;
    const cv::Point3f& p = reference.points_C[static_cast<std::size_t>(m.trainIdx)];
    object.emplace_back(sx * p.x, sy * p.y, p.z);
    image.push_back(current.keypoints[static_cast<std::size_t>(m.queryIdx)].pt);
    current_index.push_back(m.queryIdx);
  }
  const int matches = static_cast<int>(object.size());
  if (matches < config.min_inliers) return std::nullopt;

  const cv::Matx33d camera(std::abs(k.fx), 0, k.cx, 0, std::abs(k.fy), k.cy, 0, 0, 1);
  cv::Mat rvec, tvec;
  std::vector<int> inliers;
  // EPnP on the minimal samples: P3P (AP3P) and SQPnP measured no better, ITERATIVE failed
  // on most office pairs; OpenCV stops early once the inlier ratio makes 0.999 confident.
  const bool found = cv::solvePnPRansac(
      object, image, camera, cv::noArray(), rvec, tvec, false, config.ransac_iterations,
      static_cast<float>(config.ransac_reprojection_px), 0.999, inliers, cv::SOLVEPNP_EPNP);
  if (!found || static_cast<int>(inliers.size()) < config.min_inliers) return std::nullopt;

  // Refine on the inliers, then take the inliers again with the refined pose. An inlier whose
  // depth in the current frame contradicts the pose (a T-junction, an occluding edge) goes even
  // when it reprojects well: over a 30 cm baseline, 15 cm of depth error at 3 m moves a point
  // only about 3 px.
  std::vector<cv::Point3f> inlier_object;
  std::vector<cv::Point2f> inlier_image;
  const auto refine = [&] {
    inlier_object.clear();
    inlier_image.clear();
    for (const int i : inliers) {
      inlier_object.push_back(object[static_cast<std::size_t>(i)]);
      inlier_image.push_back(image[static_cast<std::size_t>(i)]);
    }
    cv::solvePnPRefineLM(inlier_object, inlier_image, camera, cv::noArray(), rvec, tvec);
  };
  int with_depth = 0, agreeing = 0;
  for (int pass = 0; pass < 2; ++pass) {
    refine();
    std::vector<cv::Point2f> projected;
    cv::projectPoints(object, rvec, tvec, camera, cv::noArray(), projected);
    cv::Matx33d R;
    cv::Rodrigues(rvec, R);
    const cv::Vec3d t(tvec.at<double>(0), tvec.at<double>(1), tvec.at<double>(2));
    inliers.clear();
    with_depth = agreeing = 0;
    for (int i = 0; i < matches; ++i) {
      const auto j = static_cast<std::size_t>(i);
      if (cv::norm(projected[j] - image[j]) > config.ransac_reprojection_px) continue;
      // Depth is the same in flipped coordinates.
      const cv::Point3f& o = object[j];
      const double z = (R * cv::Vec3d(o.x, o.y, o.z) + t)[2];
      if (z <= 0.0) continue;
      const cv::Point3f& seen = current.points_C[static_cast<std::size_t>(current_index[j])];
      if (finite(seen)) {
        ++with_depth;
        if (std::abs(seen.z - z) > config.depth_tolerance_fraction * z) continue;
        ++agreeing;
      }
      inliers.push_back(i);
    }
    if (static_cast<int>(inliers.size()) < config.min_inliers) return std::nullopt;
  }
  // A wrong pose can reproject many matches yet disagree with the depth seen at them.
  if (agreeing < config.min_depth_agreement * with_depth) return std::nullopt;
  refine();

  std::vector<cv::Point2f> projected;
  cv::Mat jacobian;  // 2N x (3 rvec + 3 tvec + intrinsics ...)
  cv::projectPoints(inlier_object, rvec, tvec, camera, cv::noArray(), projected, jacobian);
  double squared_error = 0.0;
  for (std::size_t j = 0; j < projected.size(); ++j) {
    const cv::Point2f d = projected[j] - inlier_image[j];
    squared_error += d.x * d.x + d.y * d.y;
  }
  const double rms = std::sqrt(squared_error / static_cast<double>(projected.size()));
  Eigen::MatrixXd J;
  cv::cv2eigen(jacobian.colRange(0, 6), J);
  const Eigen::Matrix<double, 6, 6> covariance =
      rms * rms * (J.transpose() * J).inverse();  // rvec, tvec
  const double rotation_sigma_deg =
      std::sqrt(covariance.topLeftCorner<3, 3>().eigenvalues().real().maxCoeff()) * 180.0 / M_PI;
  const double translation_sigma_m =
      std::sqrt(covariance.bottomRightCorner<3, 3>().eigenvalues().real().maxCoeff());
  if (!(translation_sigma_m <= config.max_translation_sigma_m &&
        rotation_sigma_deg <= config.max_rotation_sigma_deg)) {  // also NaN: singular geometry
    return std::nullopt;  // the inliers do not pin the pose down (few, clustered or collinear)
  }

  cv::Matx33d R_flipped;
  cv::Rodrigues(rvec, R_flipped);
  Eigen::Matrix3d R;
  Eigen::Vector3d t;
  cv::cv2eigen(R_flipped, R);
  cv::cv2eigen(tvec, t);
  const Eigen::Vector3d flip(sx, sy, 1.0);
  FeaturePose pose;
  pose.T_current_reference.linear() = flip.asDiagonal() * R * flip.asDiagonal();
  pose.T_current_reference.translation() = flip.asDiagonal() * t;
  pose.matches = matches;
  pose.inliers = static_cast<int>(inliers.size());
  pose.reprojection_rms_px = rms;
  pose.translation_sigma_m = translation_sigma_m;
  pose.rotation_sigma_deg = rotation_sigma_deg;
  return pose;
}

}  // namespace

std::optional<FeaturePose> estimateFeaturePose(const FeatureFrame& reference,
                                               const FeatureFrame& current,
                                               const core::Intrinsics& k,
                                               const FeaturePoseConfig& config) {
  try {
    return estimate(reference, current, k, config);
  } catch (const cv::Exception&) {
    return std::nullopt;  // degenerate point sets (all collinear, ...): no pose
  }
}

}  // namespace tessera::fusion
