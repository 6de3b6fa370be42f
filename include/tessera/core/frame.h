#pragma once
// One RGB-D frame as every stage sees it.
#include <cstdint>
#include <optional>

#include <opencv2/core/mat.hpp>

#include "tessera/core/intrinsics.h"
#include "tessera/core/pose.h"

namespace tessera::core {

struct Frame {
  std::uint64_t index = 0;           // position in the source, from 0
  std::int64_t timestamp_ns = 0;     // capture time
  cv::Mat depth_mm;                  // CV_16UC1, millimetres, 0 = invalid
  cv::Mat rgb;                       // CV_8UC3 in R, G, B order, registered to depth
  Intrinsics intrinsics;             // of depth_mm (and of rgb when it has the same size)
  std::optional<Isometry> T_W_C_gt;  // ground-truth camera-to-world pose, when the source has one
};

}  // namespace tessera::core
