// Writes a 240 x 200 PNG of a random tile repeated by the lattice (24, 0), (9, 16), for the
// `tessera pattern` command's end-to-end test.
#include <cstdio>

#include <opencv2/imgcodecs.hpp>

#include "pattern/pattern_test_support.h"

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: make_test_tiling OUT.png\n");
    return 2;
  }
  const cv::Mat tile = tessera::pattern::testing::randomTile(24, 16, 3);
  const cv::Mat rgb = tessera::pattern::testing::tiling(tile, {{24.0, 0.0}, {9.0, 16.0}}, 240, 200);
  cv::Mat bgr;
  cv::cvtColor(rgb, bgr, cv::COLOR_RGB2BGR);
  return cv::imwrite(argv[1], bgr) ? 0 : 1;
}
