#pragma once
// Drift correction against the patch map: a frame's regions, placed at the tracked pose, are
// pulled onto the planes of the established patches they continue (point-to-plane least
// squares over a small rigid motion). Tracking drifts slowly, so the correction found for one
// frame is carried to the next; planes seen early then anchor the ones seen later.
#include <optional>
#include <vector>

#include "tessera/core/pose.h"
#include "tessera/planes/patch_map.h"

namespace tessera::planes {

struct PlaneAlignmentConfig {
  bool enabled = false;            // adds error to the keyframe tracker (config/default.yaml)
  double min_patch_area_m2 = 0.5;  // only patches this large ...
  int min_patch_frames = 15;       // ... and seen in this many frames anchor the pose
  int points_per_region = 400;     // points of each region used (evenly spread)
  double max_step_m = 0.03;        // a larger correction in one frame (camera motion) is not
  double max_step_deg = 1.5;       // trusted: the region was probably matched wrongly
};

// The rigid motion D (applied on the left, world frame) that best moves the observations onto
// the planes of the established patches they continue; nothing when no region continues one.
// Rotations are about the camera centre. Directions the matched planes do not constrain (all
// of them parallel, say) are left unmoved.
std::optional<core::Isometry> alignToPatches(const PatchMap& map,
                                             const std::vector<PlaneObservation>& observations_W,
                                             const Eigen::Vector3d& camera_centre_W,
                                             const PlaneAlignmentConfig& config);

}  // namespace tessera::planes
