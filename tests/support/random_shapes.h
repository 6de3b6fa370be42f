#pragma once
// A seeded test texture: small shapes in a few random colours, densely over a plain ground.
// Features everywhere and the same statistics in every part (as a surface's texture has), so
// that a crop's colour coherence is close to the whole's.
#include <random>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

namespace tessera::test {

inline cv::Mat randomShapes(int width, int height, unsigned seed) {
  std::mt19937 random(seed);
  std::uniform_int_distribution<int> level(0, 255), x(0, width - 1), y(0, height - 1), size(3, 9);
  const cv::Scalar ground(level(random), level(random), level(random));
  std::vector<cv::Scalar> palette;
  for (int i = 0; i < 4; ++i) palette.emplace_back(level(random), level(random), level(random));
  cv::Mat image(height, width, CV_8UC3, ground);
  for (int i = 0; i < width * height / 60; ++i) {
    const cv::Scalar c = palette[static_cast<std::size_t>(i) % palette.size()];
    const cv::Point p(x(random), y(random));
    if (i % 2 == 0) {
      cv::circle(image, p, size(random), c, cv::FILLED, cv::LINE_AA);
    } else {
      cv::rectangle(image, p, p + cv::Point(size(random), size(random)), c, cv::FILLED);
    }
  }
  return image;
}

}  // namespace tessera::test
