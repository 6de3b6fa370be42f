#pragma once
// The tracker's keyframe record of a rendered frame, for loop-closure tests. Tests that include
// it link tessera_fusion and opencv_imgproc.
#include <cstdint>
#include <limits>

#include <opencv2/imgproc.hpp>

#include "tessera/core/frame.h"
#include "tessera/core/registration.h"
#include "tessera/fusion/feature_pose.h"
#include "tessera/fusion/tracker.h"

namespace tessera::test {

// `frame` as a keyframe posed at T_W_C at `timestamp_ns`: ORB features of its registered
// colour with their depth, depth in metres (NaN where missing).
inline fusion::KeyframeRecord keyframeRecordOf(const core::Frame& frame,
                                               const core::Isometry& T_W_C,
                                               std::int64_t timestamp_ns) {
  fusion::KeyframeRecord record;
  cv::Mat grey;
  cv::cvtColor(core::registerColourToDepth(frame), grey, cv::COLOR_RGB2GRAY);
  frame.depth_mm.convertTo(record.depth_m, CV_32F, 1e-3);
  record.depth_m.setTo(std::numeric_limits<float>::quiet_NaN(), frame.depth_mm == 0);
  record.features = std::make_shared<const fusion::FeatureFrame>(fusion::describeFeatures(
      grey, record.depth_m, frame.intrinsics, fusion::FeaturePoseConfig{}));
  record.timestamp_ns = timestamp_ns;
  record.T_W_C = T_W_C;
  record.intrinsics = frame.intrinsics;
  return record;
}

}  // namespace tessera::test
