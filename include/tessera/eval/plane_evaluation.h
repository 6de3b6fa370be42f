#pragma once
// Plane recall and precision (docs/METRICS.md): the finalized patches of a run (patches.json)
// against the planes of a synthetic scene's ground truth (.gt.json).
#include <cstddef>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "tessera/core/pose.h"
#include "tessera/core/trajectory.h"

namespace tessera::eval {

struct PlaneEvaluationOptions {
  double max_depth_m = 4.0;     // a plane is seen where the camera sees it nearer than this
  double min_seen_m2 = 0.25;    // ground-truth planes seen less than this are not counted
  double max_normal_deg = 2.0;  // a patch matches a plane within these bounds...
  double max_offset_m = 0.01;
  double min_iou = 0.8;  // ... and finds it with at least this outline IoU
  // Duplicates: patches within these looser bounds of one plane (a wall mapped twice after
  // drift lies centimetres off) whose cells overlap by at least min_duplicate_overlap of the
  // smaller one cover that plane twice.
  double duplicate_normal_deg = 10.0;
  double duplicate_offset_m = 0.15;
  double min_duplicate_overlap = 0.2;
  double cell_m = 0.05;  // raster of the plane in which seen area and IoU are measured
  int frame_step = 4;    // visibility from every N-th ground-truth pose ...
  int pixel_step = 4;    // ... and every N-th pixel
};

struct PlaneResult {
  std::string id;
  double seen_m2 = 0.0;
  bool counted = false;  // seen at least min_seen_m2
  bool found = false;
  int patch_id = -1;  // best matching patch, or -1
  double iou = 0.0;
  double normal_error_deg = 0.0;
  double offset_error_m = 0.0;
  int duplicates = 0;  // patches covering part of this plane that another patch covers too
};

struct PlaneEvaluation {
  std::size_t planes_counted = 0;
  std::size_t planes_found = 0;
  std::size_t patches = 0;          // the run's planes: the tiles of one plane count once
  std::size_t patches_matched = 0;  // the best match of some ground-truth plane
  double recall = 0.0;              // planes_found / planes_counted (0 when none is counted)
  double precision = 0.0;           // patches_matched / patches (0 when there is no patch)
  std::size_t duplicate_patches = 0;  // summed over the planes
  std::vector<PlaneResult> planes;
};

// `truth` is a parsed .gt.json with "planes" and "intrinsics", `truth_poses` its camera poses
// (what the camera saw is ray-cast from them), `patches` a parsed patches.json. T_gt_est maps
// the run's world frame onto the truth's (the trajectory alignment). Overlay planes (a poster lying
// on a wall, within the offset bound) count as part of the plane they lie on. Throws core::Error
// when a file lacks what is needed.
PlaneEvaluation evaluatePlanes(const nlohmann::json& truth, const core::Trajectory& truth_poses,
                               const nlohmann::json& patches, const core::Isometry& T_gt_est,
                               const PlaneEvaluationOptions& options = {});

}  // namespace tessera::eval
