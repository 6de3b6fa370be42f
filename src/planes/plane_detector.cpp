#include "tessera/planes/plane_detector.h"

#include <fmt/format.h>
#include <opencv2/rgbd.hpp>

#include "tessera/core/error.h"
#include "tessera/planes/plane_fit.h"

namespace tessera::planes {

PlaneDetector::PlaneDetector(const PlaneDetectorConfig& config) : config_(config) {}

namespace {

// Camera-frame points of every `step`-th pixel; invalid depth gives NaN, as RgbdPlane expects.
cv::Mat organisedPoints(const core::Frame& frame, int step, double min_m, double max_m) {
  const core::Intrinsics& k = frame.intrinsics;
  const int width = k.width / step, height = k.height / step;
  cv::Mat points(height, width, CV_32FC3);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  for (int v = 0; v < height; ++v) {
    const auto* depth = frame.depth_mm.ptr<std::uint16_t>(v * step);
    auto* out = points.ptr<cv::Vec3f>(v);
    for (int u = 0; u < width; ++u) {
      const double z = depth[u * step] * 1e-3;
      if (z < min_m || z > max_m) {
        out[u] = cv::Vec3f(nan, nan, nan);
        continue;
      }
      out[u] = cv::Vec3f(static_cast<float>((u * step - k.cx) * z / k.fx),
                         static_cast<float>((v * step - k.cy) * z / k.fy), static_cast<float>(z));
    }
  }
  return points;
}

// Least-squares plane of the points labelled `label`, its normal facing the camera.
DetectedPlane refit(const cv::Mat& points, const cv::Mat& labels, int label) {
  PointMoments moments;
  for (int v = 0; v < labels.rows; ++v) {
    const auto* l = labels.ptr<std::uint8_t>(v);
    const auto* p = points.ptr<cv::Vec3f>(v);
    for (int u = 0; u < labels.cols; ++u) {
      if (l[u] == label) moments.add(Eigen::Vector3d(p[u][0], p[u][1], p[u][2]));
    }
  }
  const PlaneFit fit = fitPlane(moments);
  DetectedPlane plane;
  plane.pixels = static_cast<std::size_t>(moments.count);
  plane.centroid_C = fit.centroid;
  plane.normal_C = fit.normal.dot(fit.centroid) > 0.0 ? Eigen::Vector3d(-fit.normal) : fit.normal;
  plane.offset_C = plane.normal_C.dot(plane.centroid_C);
  plane.rms_residual_m = fit.rms_residual_m;
  return plane;
}

}  // namespace

PlaneDetection PlaneDetector::detect(const core::Frame& frame) const {
  const core::Intrinsics& k = frame.intrinsics;
  if (!k.valid() || frame.depth_mm.type() != CV_16UC1 || frame.depth_mm.cols != k.width ||
      frame.depth_mm.rows != k.height) {
    throw core::Error(fmt::format("frame {}: depth {}x{} does not match intrinsics {}", frame.index,
                                  frame.depth_mm.cols, frame.depth_mm.rows, k.describe()));
  }
  PlaneDetection detection;
  detection.scale = config_.working_scale;
  const cv::Mat points =
      organisedPoints(frame, config_.working_scale, config_.min_depth_m, config_.max_depth_m);

  // Error model: a point belongs to a plane within threshold + a z^2 (RgbdPlane's
  // sensor_error terms), so far, noisier depth is not split into slivers.
  const cv::Ptr<cv::rgbd::RgbdPlane> finder = cv::rgbd::RgbdPlane::create(
      cv::rgbd::RgbdPlane::RGBD_PLANE_METHOD_DEFAULT, config_.block_size, config_.min_pixels,
      config_.threshold_m, config_.sensor_error_a, 0.0, 0.0);
  cv::Mat coefficients;
  try {
    (*finder)(points, detection.labels, coefficients);
  } catch (const cv::Exception& e) {
    throw core::Error(fmt::format("frame {}: plane detection failed: {}", frame.index, e.what()));
  }
  if (detection.labels.empty()) {
    detection.labels = cv::Mat(points.size(), CV_8UC1, cv::Scalar(PlaneDetection::kNoPlane));
  }
  const int found = std::min(coefficients.rows, static_cast<int>(PlaneDetection::kNoPlane));
  // RgbdPlane keeps only regions of at least min_pixels, so every label has points.
  for (int label = 0; label < found; ++label) {
    detection.planes.push_back(refit(points, detection.labels, label));
  }
  return detection;
}

}  // namespace tessera::planes
