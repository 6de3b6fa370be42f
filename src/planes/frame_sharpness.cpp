#include "tessera/planes/frame_sharpness.h"

#include <algorithm>
#include <vector>

#include <opencv2/imgproc.hpp>

namespace tessera::planes {

double gradientEnergy(const cv::Mat& rgb) {
  if (rgb.empty()) return 0.0;
  cv::Mat grey, small, dx, dy;
  if (rgb.channels() == 3) {
    cv::cvtColor(rgb, grey, cv::COLOR_RGB2GRAY);
  } else {
    grey = rgb;
  }
  // Half resolution: sensor noise has little gradient energy there, blur still shows.
  cv::resize(grey, small, cv::Size(), 0.5, 0.5, cv::INTER_AREA);
  cv::Sobel(small, dx, CV_32F, 1, 0);
  cv::Sobel(small, dy, CV_32F, 0, 1);
  return cv::mean(dx.mul(dx) + dy.mul(dy))[0];
}

double SharpnessGauge::measure(const cv::Mat& rgb) {
  const double energy = gradientEnergy(rgb);
  if (energy <= 0.0) return 1.0;
  double factor = 1.0;
  if (!recent_.empty()) {
    std::vector<double> sorted(recent_.begin(), recent_.end());
    std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
    const double median = sorted[sorted.size() / 2];
    factor = std::clamp(energy / median, kFloor, 1.0);
  }
  recent_.push_back(energy);
  while (recent_.size() > window_) recent_.pop_front();
  return factor;
}

}  // namespace tessera::planes
