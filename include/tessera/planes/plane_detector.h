#pragma once
// Per-frame detection of planar regions in organised depth. A plane in 3-D is also a plane in
// (u, v, disparity), and a structured-light sensor's noise and quantisation are nearly uniform
// in disparity, so OpenCV's RgbdPlane grows regions there with one threshold for every range.
// Each region is then refitted in 3-D by least squares, dropping pixels off the fitted plane.
#include <cstddef>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core/mat.hpp>

#include "tessera/core/frame.h"

namespace tessera::planes {

struct PlaneDetectorConfig {
  int working_scale = 2;  // detect on every N-th pixel (2: 320x240 from 640x480)
  int block_size = 20;    // side of the seed blocks, pixels at working resolution
  // Disparity is measured in pixels of a Kinect-like stereo pair (focal length fx of the
  // frame, baseline below); the Kinect v1 quantises it in steps of 1/8 pixel.
  double baseline_m = 0.075;
  // Largest disparity distance of a pixel from its region's plane, and largest RMS of a seed
  // block; 0.2 px is 5 mm at 1 m and 4.6 cm at 3 m, where depth steps are 2.9 cm.
  double threshold_px = 0.2;
  // After the 3-D refit, pixels whose disparity is farther than this from the refitted plane
  // leave the region (the foot of a wall grown into the floor, say).
  double refit_threshold_px = 0.15;
  // Strips of a region narrower than this (pixels at working resolution) are removed: they
  // are other surfaces running along the line where they meet the plane.
  int strip_width_px = 7;
  int min_pixels = 1200;  // smallest region, pixels at working resolution
  double min_depth_m = 0.3;
  double max_depth_m = 4.0;
};

// One planar region in camera coordinates: n . X = d, n unit and facing the camera (d < 0
// for a plane in front of it, since n points back towards the origin).
struct DetectedPlane {
  Eigen::Vector3d normal_C;
  double offset_C = 0.0;
  Eigen::Vector3d centroid_C;
  std::size_t pixels = 0;       // at working resolution
  double rms_residual_m = 0.0;  // of its points about the refitted plane
};

struct PlaneDetection {
  cv::Mat labels;  // CV_8UC1 at working resolution: plane index, or kNoPlane
  std::vector<DetectedPlane> planes;
  int scale = 1;  // labels pixel (u, v) is frame pixel (scale * u, scale * v)
  static constexpr std::uint8_t kNoPlane = 255;
};

class PlaneDetector {
 public:
  explicit PlaneDetector(const PlaneDetectorConfig& config);

  // Throws core::Error when the frame's depth does not match its intrinsics.
  PlaneDetection detect(const core::Frame& frame) const;

 private:
  PlaneDetectorConfig config_;
};

}  // namespace tessera::planes
