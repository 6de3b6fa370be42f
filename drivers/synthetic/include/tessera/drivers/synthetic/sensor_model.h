#pragma once
// What an RGB-D sensor does to a perfect rendering: resolution, range, depth quantisation and
// noise, dropouts at edges and grazing angles, colour noise and blur.
#include <cstdint>
#include <string>

#include <opencv2/core/mat.hpp>

#include "tessera/core/intrinsics.h"

namespace tessera::drivers::synthetic {

struct SensorProfile {
  std::string name = "kinect_v1";
  core::Intrinsics intrinsics;  // depth camera; colour is registered to it
  double min_depth_m = 0.5;
  double max_depth_m = 4.5;
  // Kinect v1 measures disparity in 1/8 pixel steps: z = baseline * focal / disparity.
  bool disparity_quantisation = true;
  double baseline_m = 0.075;
  double disparity_focal_px = 580.0;
  double disparity_step_px = 0.125;
  // Axial noise sigma(z) = a + b (z - c)^2, metres (Nguyen, Izadi, Lovell 2012, for Kinect v1).
  double noise_a_m = 0.0012;
  double noise_b = 0.0019;
  double noise_c_m = 0.4;
  double grazing_start_deg = 70.0;   // dropout probability rises from 0 here ...
  double grazing_full_deg = 85.0;    // ... to 1 here
  double edge_jump_fraction = 0.04;  // depth jump (fraction of z) that makes a pixel an edge
  double edge_dropout = 0.6;         // probability an edge pixel is lost
  double colour_noise_sigma = 2.0;   // 8-bit levels
  double colour_blur_sigma_px = 0.6;
  // Colour registered to depth (rendered from the depth camera), or taken by its own camera
  // `colour_baseline_m` along the depth camera's +x axis, as an unregistered Kinect delivers it.
  bool colour_registered = true;
  double colour_baseline_m = 0.025;

  // Named profiles: "kinect_v1" (640x480), "kinect_v2" (512x424 time of flight, no
  // quantisation), "ideal" (kinect_v1 geometry, no noise, no dropouts, no blur).
  static SensorProfile named(const std::string& name);
  static std::string knownNames();
};

// Perfect images of one view, before the sensor model.
struct CleanView {
  cv::Mat depth_m;        // CV_64FC1, 0 where nothing is hit
  cv::Mat colour;         // CV_32FC3 RGB in [0, 255]
  cv::Mat cos_incidence;  // CV_64FC1, |cos| of the angle between ray and surface normal
  cv::Mat surface_id;     // CV_32SC1: plane index, -1 clutter, -2 nothing
};

// Applies the profile to a clean view. Deterministic for `seed`.
void applySensor(const SensorProfile& profile, const CleanView& view, std::uint64_t seed,
                 cv::Mat& depth_mm, cv::Mat& rgb);

// Standard deviation of the axial depth noise at z metres (0 for a noise-free profile).
double depthNoiseSigma(const SensorProfile& profile, double z_m);

}  // namespace tessera::drivers::synthetic
