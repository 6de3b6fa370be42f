#pragma once
// How sharp a colour frame is next to the frames just before it. Motion blur lowers the mean
// squared intensity gradient, while what the camera sees changes slowly from frame to frame,
// so a frame well below the recent median was blurred by motion and its colours should count
// for less.
#include <cstddef>
#include <deque>

#include <opencv2/core/mat.hpp>

namespace tessera::planes {

class SharpnessGauge {
 public:
  explicit SharpnessGauge(std::size_t window_frames = 30) : window_(window_frames) {}

  // The frame's weight factor in [kFloor, 1]: 1 for a frame at least as sharp as the median of
  // the window, its gradient energy over that median below it. Empty images give 1.
  double measure(const cv::Mat& rgb);

  static constexpr double kFloor = 0.05;

 private:
  std::size_t window_;
  std::deque<double> recent_;  // gradient energy of the last frames
};

// Mean squared Sobel gradient of the image's grey levels at half resolution.
double gradientEnergy(const cv::Mat& rgb);

}  // namespace tessera::planes
