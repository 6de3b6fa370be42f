#pragma once
// Frames of the synthetic office (config/scenes/office.yaml) from chosen camera poses, for
// tests of tracking and pose estimation. Tests that include it link tessera_driver_synthetic.
#include <cmath>
#include <cstdint>

#include <Eigen/Geometry>

#include "tessera/core/frame.h"
#include "tessera/drivers/synthetic/renderer.h"
#include "tessera/drivers/synthetic/sensor_model.h"

namespace tessera::test {

// The office seen from T_W_C through the scene's sensor model (noise seeded by `seed`).
inline core::Frame officeFrameAt(const drivers::synthetic::Scene& scene,
                                 const core::Isometry& T_W_C, int seed) {
  core::Frame frame;
  frame.index = static_cast<std::uint64_t>(seed);
  frame.intrinsics = scene.sensor.intrinsics;
  frame.T_W_C_gt = T_W_C;
  const auto view = drivers::synthetic::renderClean(scene, frame.intrinsics, T_W_C, 1);
  drivers::synthetic::applySensor(scene.sensor, view, static_cast<std::uint64_t>(seed),
                                  frame.depth_mm, frame.rgb);
  return frame;
}

// Frame i of the office scene's own camera path.
inline core::Frame officeFrame(const drivers::synthetic::Scene& scene, int i) {
  return officeFrameAt(scene, scene.cameraPose(i), i);
}

// The camera `offset_C` (in its own frame) from the start pose, turned by `yaw_deg` about its
// vertical axis (camera y points down).
inline core::Isometry moved(const core::Isometry& start, const Eigen::Vector3d& offset_C,
                            double yaw_deg) {
  core::Isometry T = start;
  T.translation() += start.linear() * offset_C;
  T.linear() =
      start.linear() *
      Eigen::AngleAxisd(yaw_deg * M_PI / 180.0, Eigen::Vector3d::UnitY()).toRotationMatrix();
  return T;
}

// The angle of the rotation between two poses, degrees.
inline double rotationErrorDeg(const core::Isometry& a, const core::Isometry& b) {
  return Eigen::AngleAxisd(a.linear().transpose() * b.linear()).angle() * 180.0 / M_PI;
}

}  // namespace tessera::test
