#pragma once
// Exact depth images of a plane, for tests with known ground truth.
#include <cmath>
#include <cstdint>

#include <opencv2/core.hpp>

#include "tessera/core/frame.h"

namespace tessera::test {

// Renders the plane n . X_W = d (n unit, world frame) as seen from T_W_C: each pixel's ray
// meets the plane at depth z, stored in millimetres rounded to the nearest; pixels whose ray
// misses the plane or lands beyond max_depth_m are 0. Colour is a checkerboard on the plane.
inline core::Frame renderPlane(const core::Intrinsics& k, const core::Isometry& T_W_C,
                               const Eigen::Vector3d& n_W, double d_W, double max_depth_m = 5.0) {
  core::Frame frame;
  frame.intrinsics = k;
  frame.depth_mm = cv::Mat(k.height, k.width, CV_16UC1, cv::Scalar(0));
  frame.rgb = cv::Mat(k.height, k.width, CV_8UC3, cv::Scalar(0, 0, 0));
  const Eigen::Vector3d origin = T_W_C.translation();
  for (int v = 0; v < k.height; ++v) {
    for (int u = 0; u < k.width; ++u) {
      // Ray with unit z in the camera frame, so the ray parameter is the depth z.
      const Eigen::Vector3d ray_C((u - k.cx) / k.fx, (v - k.cy) / k.fy, 1.0);
      const Eigen::Vector3d ray_W = T_W_C.linear() * ray_C;
      const double denominator = n_W.dot(ray_W);
      if (std::abs(denominator) < 1e-9) continue;
      const double z = (d_W - n_W.dot(origin)) / denominator;
      if (z <= 0.0 || z > max_depth_m) continue;
      frame.depth_mm.at<std::uint16_t>(v, u) = static_cast<std::uint16_t>(std::lround(z * 1000));
      const Eigen::Vector3d X = origin + z * ray_W;
      const bool dark =
          (static_cast<long>(std::floor(X.x() * 10)) + static_cast<long>(std::floor(X.y() * 10)) +
           static_cast<long>(std::floor(X.z() * 10))) %
              2 !=
          0;
      frame.rgb.at<cv::Vec3b>(v, u) = dark ? cv::Vec3b(40, 40, 40) : cv::Vec3b(220, 200, 180);
    }
  }
  return frame;
}

inline core::Intrinsics kinectIntrinsics() {
  core::Intrinsics k;
  k.width = 640, k.height = 480, k.fx = 525.0, k.fy = 525.0, k.cx = 319.5, k.cy = 239.5;
  return k;
}

}  // namespace tessera::test
