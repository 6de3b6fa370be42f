#pragma once
// Per-frame detection of planar regions in organised depth. OpenCV's RgbdPlane grows regions
// from blocks of pixels whose points fit a plane (with a depth-dependent error model for the
// Kinect), then each region's plane is refitted to all its points by least squares.
#include <cstddef>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core/mat.hpp>

#include "tessera/core/frame.h"

namespace tessera::planes {

struct PlaneDetectorConfig {
  int working_scale = 2;      // detect on every N-th pixel (2: 320x240 from 640x480)
  int block_size = 20;        // side of the seed blocks, pixels at working resolution
  double threshold_m = 0.01;  // largest point-to-plane distance at 1 m
  // Depth error model: the threshold grows by a * z^2. OpenCV suggests 0.0075 for a Kinect,
  // which merged the floor with the foot of walls at 2.5 m here (offsets off by 4 cm); 0.001
  // kept every office plane within 7 mm.
  double sensor_error_a = 0.001;
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
