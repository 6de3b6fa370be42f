#pragma once
// The loop a user would write with Open3D alone, as the benchmarks' point of comparison: its
// legacy RGB-D odometry (hybrid term, default options) frame to frame and ScalableTSDFVolume
// at full resolution with tessera's voxels. Open3D's headers stay in open3d_loop.cpp.
#include <optional>
#include <vector>

#include "tessera/core/frame.h"
#include "tessera/fusion/tsdf_map.h"

namespace tessera::bench {

struct PlainLoopResult {
  double ms_per_frame = 0.0;
  std::optional<double> ate_mm;  // when every frame has a ground-truth pose
  int ate_poses = 0;
  int odometry_failures = 0;  // frames that kept the previous pose
};

// Runs the loop over `frames` (millimetre depth, colour registered to depth). It starts at the
// first frame's ground-truth pose when there is one, else at the identity.
PlainLoopResult plainOpen3dLoop(const std::vector<core::Frame>& frames,
                                const fusion::TsdfConfig& tsdf);

}  // namespace tessera::bench
