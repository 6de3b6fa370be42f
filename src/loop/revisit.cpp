#include "tessera/loop/revisit.h"

#include <cmath>
#include <memory>

#include <fmt/format.h>
#include <open3d/geometry/KDTreeSearchParam.h>
#include <open3d/geometry/PointCloud.h>
#include <open3d/pipelines/registration/Registration.h>
#include <open3d/pipelines/registration/TransformationEstimation.h>

namespace tessera::loop {

namespace o3d = open3d;
namespace reg = open3d::pipelines::registration;

cv::Mat strideDepth(const cv::Mat& depth_m, int stride) {
  cv::Mat out(depth_m.rows / stride, depth_m.cols / stride, CV_32F);
  for (int v = 0; v < out.rows; ++v) {
    for (int u = 0; u < out.cols; ++u) {
      const float z = depth_m.at<float>(v * stride, u * stride);
      out.at<float>(v, u) = std::isfinite(z) && z > 0.0f ? z : std::nanf("");
    }
  }
  return out;
}

namespace {

// The keyframe's depth as points in its camera, with normals from their 20 nearest neighbours
// when asked (point-to-plane ICP's target needs them).
std::shared_ptr<o3d::geometry::PointCloud> cloudOf(const KeyframeView& key, int stride,
                                                   double max_depth_m, bool normals) {
  auto cloud = std::make_shared<o3d::geometry::PointCloud>();
  const core::Intrinsics& k = key.intrinsics;
  for (int v = 0; v < key.depth_m.rows; ++v) {
    const float* row = key.depth_m.ptr<float>(v);
    for (int u = 0; u < key.depth_m.cols; ++u) {
      const double z = row[u];
      if (!std::isfinite(z) || z > max_depth_m) continue;
      const double px = u * stride, py = v * stride;
      cloud->points_.emplace_back((px - k.cx) * z / k.fx, (py - k.cy) * z / k.fy, z);
    }
  }
  if (normals) {
    cloud->EstimateNormals(o3d::geometry::KDTreeSearchParamKNN(20));
    cloud->OrientNormalsTowardsCameraLocation(Eigen::Vector3d::Zero());
  }
  return cloud;
}

}  // namespace

std::optional<Revisit> verifyRevisit(const KeyframeView& match, const KeyframeView& query,
                                     const LoopConfig& config, std::string& why) {
  const auto pose = fusion::estimateFeaturePose(*match.features, *query.features, query.intrinsics,
                                                config.features);
  if (!pose) {
    why = "features give no pose";
    return std::nullopt;
  }
  const auto source = cloudOf(match, config.dense_stride, config.dense_max_depth_m, false);
  const auto target = cloudOf(query, config.dense_stride, config.dense_max_depth_m, true);
  if (source->points_.size() < 100 || target->points_.size() < 100) {
    why = "too little depth";
    return std::nullopt;
  }
  const reg::RegistrationResult icp = reg::RegistrationICP(
      *source, *target, config.icp_distance_m, pose->T_current_reference.matrix(),
      reg::TransformationEstimationPointToPlane(), reg::ICPConvergenceCriteria(1e-6, 1e-6, 30));
  if (icp.fitness_ < config.min_fitness || icp.inlier_rmse_ > config.max_icp_rmse_m) {
    why = fmt::format("dense check failed (fitness {:.2f}, rms {:.1f} mm)", icp.fitness_,
                      icp.inlier_rmse_ * 1e3);
    return std::nullopt;
  }
  Revisit out;
  out.T_query_match.matrix() = icp.transformation_;
  out.feature_inliers = pose->inliers;
  out.fitness = icp.fitness_;
  out.rmse_m = icp.inlier_rmse_;
  out.information = reg::GetInformationMatrixFromPointClouds(*source, *target,
                                                             config.icp_distance_m,
                                                             icp.transformation_);
  return out;
}

Matrix6d edgeInformation(const KeyframeView& source, const KeyframeView& target,
                         const core::Isometry& T_target_source, const LoopConfig& config) {
  const auto a = cloudOf(source, config.dense_stride, config.dense_max_depth_m, false);
  const auto b = cloudOf(target, config.dense_stride, config.dense_max_depth_m, false);
  if (a->points_.empty() || b->points_.empty()) return Matrix6d::Identity();
  return reg::GetInformationMatrixFromPointClouds(*a, *b, config.icp_distance_m,
                                                  T_target_source.matrix());
}

}  // namespace tessera::loop
