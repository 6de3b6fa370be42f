#include "tessera/planes/plane_detector.h"

#include <cmath>
#include <limits>
#include <utility>
#include <vector>

#include <fmt/format.h>
#include <opencv2/imgproc.hpp>
#include <opencv2/rgbd.hpp>

#include "tessera/core/error.h"
#include "tessera/planes/plane_fit.h"

namespace tessera::planes {

PlaneDetector::PlaneDetector(const PlaneDetectorConfig& config) : config_(config) {}

namespace {

// Per working pixel: the camera-frame point, and the same pixel as (u, v, disparity), the space
// RgbdPlane searches. Invalid depth gives NaN, as RgbdPlane expects.
struct OrganisedPoints {
  cv::Mat points_C;   // CV_32FC3
  cv::Mat disparity;  // CV_32FC3: u, v in working pixels, disparity in pixels
};

OrganisedPoints organisedPoints(const core::Frame& frame, const PlaneDetectorConfig& config) {
  const core::Intrinsics& k = frame.intrinsics;
  const int step = config.working_scale;
  const int width = k.width / step, height = k.height / step;
  const double focal_baseline = k.fx * config.baseline_m;
  OrganisedPoints out{cv::Mat(height, width, CV_32FC3), cv::Mat(height, width, CV_32FC3)};
  const float nan = std::numeric_limits<float>::quiet_NaN();
  for (int v = 0; v < height; ++v) {
    const auto* depth = frame.depth_mm.ptr<std::uint16_t>(v * step);
    auto* point = out.points_C.ptr<cv::Vec3f>(v);
    auto* uvw = out.disparity.ptr<cv::Vec3f>(v);
    for (int u = 0; u < width; ++u) {
      const double z = depth[u * step] * 1e-3;
      if (z < config.min_depth_m || z > config.max_depth_m) {
        point[u] = uvw[u] = cv::Vec3f(nan, nan, nan);
        continue;
      }
      point[u] = cv::Vec3f(static_cast<float>((u * step - k.cx) * z / k.fx),
                           static_cast<float>((v * step - k.cy) * z / k.fy), static_cast<float>(z));
      uvw[u] = cv::Vec3f(static_cast<float>(u), static_cast<float>(v),
                         static_cast<float>(focal_baseline / z));
    }
  }
  return out;
}

// The bounding box of each label 0..count-1 in `labels` (CV_8U); empty for a label not there.
// Each plane's refit then works in its own box, not over the whole image.
std::vector<cv::Rect> labelBoxes(const cv::Mat& labels, int count) {
  std::vector<int> x0(count, labels.cols), y0(count, labels.rows), x1(count, -1), y1(count, -1);
  for (int v = 0; v < labels.rows; ++v) {
    const auto* row = labels.ptr<std::uint8_t>(v);
    for (int u = 0; u < labels.cols; ++u) {
      const int label = row[u];
      if (label >= count) continue;
      x0[label] = std::min(x0[label], u);
      x1[label] = std::max(x1[label], u);
      y0[label] = std::min(y0[label], v);
      y1[label] = std::max(y1[label], v);
    }
  }
  std::vector<cv::Rect> boxes(static_cast<std::size_t>(count));
  for (int label = 0; label < count; ++label) {
    if (x1[label] < 0) continue;
    boxes[static_cast<std::size_t>(label)] =
        cv::Rect(cv::Point(x0[label], y0[label]), cv::Point(x1[label] + 1, y1[label] + 1));
  }
  return boxes;
}

PointMoments momentsOf(const cv::Mat& points, const cv::Mat& members) {
  PointMoments moments;
  for (int v = 0; v < members.rows; ++v) {
    const auto* m = members.ptr<std::uint8_t>(v);
    const auto* p = points.ptr<cv::Vec3f>(v);
    for (int u = 0; u < members.cols; ++u) {
      if (m[u] != 0) moments.add(Eigen::Vector3d(p[u][0], p[u][1], p[u][2]));
    }
  }
  return moments;
}

// Keeps the pixels of `region` whose disparity is within `threshold_px` of the disparity the
// plane n . X = offset predicts there: z = offset / (n . ray), ray = ((u-cx)/fx, (v-cy)/fy, 1).
// `organised` and `region` are the same window of the working image, at `corner` in it.
cv::Mat membersNear(const OrganisedPoints& organised, const cv::Mat& region,
                    const cv::Point& corner, const PlaneFit& plane, const core::Intrinsics& k,
                    const PlaneDetectorConfig& config) {
  cv::Mat members = cv::Mat::zeros(region.size(), CV_8UC1);
  const double focal_baseline = k.fx * config.baseline_m;
  const int step = config.working_scale;
  for (int v = 0; v < region.rows; ++v) {
    const auto* in = region.ptr<std::uint8_t>(v);
    const auto* uvw = organised.disparity.ptr<cv::Vec3f>(v);
    auto* out = members.ptr<std::uint8_t>(v);
    for (int u = 0; u < region.cols; ++u) {
      if (in[u] == 0) continue;
      const Eigen::Vector3d ray(((u + corner.x) * step - k.cx) / k.fx,
                                ((v + corner.y) * step - k.cy) / k.fy, 1.0);
      const double predicted = focal_baseline * plane.normal.dot(ray) / plane.offset;
      if (std::abs(uvw[u][2] - predicted) <= config.refit_threshold_px) out[u] = 1;
    }
  }
  return members;
}

// The region's 3-D least-squares plane, refitted once more after dropping the pixels far from
// the first fit. Returns the members kept (CV_8U, nonzero) and the plane facing the camera.
// `organised` and `region` are the window at `corner` that holds the region: the members lie
// inside it, the opening below only removes pixels.
std::pair<cv::Mat, DetectedPlane> refit(const OrganisedPoints& organised, const cv::Mat& region,
                                        const cv::Point& corner, const core::Intrinsics& k,
                                        const PlaneDetectorConfig& config) {
  PlaneFit fit = fitPlane(momentsOf(organised.points_C, region));
  cv::Mat members = membersNear(organised, region, corner, fit, k, config);
  // Where the plane meets another surface, that surface's pixels near the intersection line
  // are within the threshold too, and region growing follows them in thin strips. An opening
  // removes strips narrower than the kernel.
  if (config.strip_width_px > 1) {
    const int side = config.strip_width_px | 1;
    cv::morphologyEx(members, members, cv::MORPH_OPEN, cv::Mat::ones(side, side, CV_8UC1),
                     cv::Point(-1, -1), 1, cv::BORDER_CONSTANT, cv::Scalar(0));
  }
  const PointMoments moments = momentsOf(organised.points_C, members);
  DetectedPlane plane;
  plane.pixels = static_cast<std::size_t>(moments.count);
  if (moments.count < 3) return {members, plane};
  fit = fitPlane(moments);
  plane.centroid_C = fit.centroid;
  plane.normal_C = fit.normal.dot(fit.centroid) > 0.0 ? Eigen::Vector3d(-fit.normal) : fit.normal;
  plane.offset_C = plane.normal_C.dot(plane.centroid_C);
  plane.rms_residual_m = fit.rms_residual_m;
  return {members, plane};
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
  const OrganisedPoints organised = organisedPoints(frame, config_);

  const cv::Ptr<cv::rgbd::RgbdPlane> finder =
      cv::rgbd::RgbdPlane::create(cv::rgbd::RgbdPlane::RGBD_PLANE_METHOD_DEFAULT,
                                  config_.block_size, config_.min_pixels, config_.threshold_px);
  cv::Mat grown;
  cv::Mat coefficients;
  try {
    (*finder)(organised.disparity, grown, coefficients);
  } catch (const cv::Exception& e) {
    throw core::Error(fmt::format("frame {}: plane detection failed: {}", frame.index, e.what()));
  }
  detection.labels =
      cv::Mat(organised.points_C.size(), CV_8UC1, cv::Scalar(PlaneDetection::kNoPlane));
  if (grown.empty()) return detection;
  const int found = std::min(coefficients.rows, static_cast<int>(PlaneDetection::kNoPlane));
  const std::vector<cv::Rect> boxes = labelBoxes(grown, found);
  for (int label = 0; label < found; ++label) {
    const cv::Rect& box = boxes[static_cast<std::size_t>(label)];
    if (box.empty()) continue;
    const OrganisedPoints window{organised.points_C(box), organised.disparity(box)};
    auto [members, plane] = refit(window, grown(box) == label, box.tl(), k, config_);
    if (plane.pixels < static_cast<std::size_t>(config_.min_pixels)) continue;
    cv::Mat labels = detection.labels(box);
    labels.setTo(static_cast<int>(detection.planes.size()), members);
    detection.planes.push_back(plane);
  }
  return detection;
}

}  // namespace tessera::planes
