#pragma once
// Reading a texture from an image file, for `tessera db import` and `tessera match`.
#include <string>

#include <opencv2/core/mat.hpp>

namespace tessera::cli {

// The RGB pixels (CV_8UC3) of an 8-bit image file and its mask (CV_8UC1, 255 = valid): the
// alpha channel when there is one, else every pixel. Throws core::Error naming the file when
// OpenCV cannot read it or it is not 8-bit.
void readTextureImage(const std::string& path, cv::Mat& rgb, cv::Mat& mask);

}  // namespace tessera::cli
