#include "texture_image.h"

#include <fmt/format.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "tessera/core/error.h"

namespace tessera::cli {

void readTextureImage(const std::string& path, cv::Mat& rgb, cv::Mat& mask) {
  const cv::Mat image = cv::imread(path, cv::IMREAD_UNCHANGED);
  if (image.empty() || image.depth() != CV_8U) {
    throw core::Error(fmt::format("{}: not an 8-bit image OpenCV can read", path));
  }
  if (image.channels() == 4) {
    cv::cvtColor(image, rgb, cv::COLOR_BGRA2RGB);
    cv::extractChannel(image, mask, 3);
    cv::threshold(mask, mask, 0, 255, cv::THRESH_BINARY);
  } else {
    cv::cvtColor(image, rgb, image.channels() == 1 ? cv::COLOR_GRAY2RGB : cv::COLOR_BGR2RGB);
    mask = cv::Mat(rgb.size(), CV_8UC1, cv::Scalar(255));
  }
}

}  // namespace tessera::cli
