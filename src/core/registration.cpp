#include "tessera/core/registration.h"

#include <cmath>

namespace tessera::core {

cv::Mat registerColourToDepth(const Frame& frame) {
  if (!frame.colour_camera) return frame.rgb;
  const Intrinsics& kd = frame.intrinsics;
  const Intrinsics& kc = frame.colour_camera->intrinsics;
  const Isometry& T_RGB_D = frame.colour_camera->T_RGB_D;
  cv::Mat registered(frame.depth_mm.size(), CV_8UC3, cv::Scalar(0, 0, 0));
  for (int v = 0; v < frame.depth_mm.rows; ++v) {
    const auto* depth = frame.depth_mm.ptr<std::uint16_t>(v);
    auto* out = registered.ptr<cv::Vec3b>(v);
    for (int u = 0; u < frame.depth_mm.cols; ++u) {
      if (depth[u] == 0) continue;
      const double z = depth[u] * 1e-3;
      const Eigen::Vector3d X_D((u - kd.cx) / kd.fx * z, (v - kd.cy) / kd.fy * z, z);
      const Eigen::Vector3d X_RGB = T_RGB_D * X_D;
      if (X_RGB.z() <= 0.0) continue;
      const double x = kc.fx * X_RGB.x() / X_RGB.z() + kc.cx;
      const double y = kc.fy * X_RGB.y() / X_RGB.z() + kc.cy;
      if (x < 0.0 || y < 0.0 || x > frame.rgb.cols - 1.0 || y > frame.rgb.rows - 1.0) continue;
      // Bilinear interpolation between the four neighbouring colour pixels.
      const int x0 = std::min(static_cast<int>(x), frame.rgb.cols - 2);
      const int y0 = std::min(static_cast<int>(y), frame.rgb.rows - 2);
      const double ax = x - x0, ay = y - y0;
      const auto& c00 = frame.rgb.at<cv::Vec3b>(y0, x0);
      const auto& c10 = frame.rgb.at<cv::Vec3b>(y0, x0 + 1);
      const auto& c01 = frame.rgb.at<cv::Vec3b>(y0 + 1, x0);
      const auto& c11 = frame.rgb.at<cv::Vec3b>(y0 + 1, x0 + 1);
      for (int c = 0; c < 3; ++c) {
        const double value =
            (c00[c] * (1 - ax) + c10[c] * ax) * (1 - ay) + (c01[c] * (1 - ax) + c11[c] * ax) * ay;
        out[u][c] = static_cast<std::uint8_t>(std::lround(value));
      }
    }
  }
  return registered;
}

Frame withRegisteredColour(Frame frame) {
  if (!frame.colour_camera) return frame;
  frame.rgb = registerColourToDepth(frame);
  frame.colour_camera.reset();
  return frame;
}

}  // namespace tessera::core
