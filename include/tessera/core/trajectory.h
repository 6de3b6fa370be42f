#pragma once
// Camera trajectories and the absolute trajectory error (ATE) as the TUM RGB-D benchmark
// defines it: associate poses by timestamp, align the estimate to the ground truth with the
// rigid transform that minimises the squared error (Horn 1987, via Eigen's Umeyama without
// scale), then take the RMSE of the translation differences.
#include <cstdint>
#include <filesystem>
#include <map>
#include <optional>
#include <string>

#include "tessera/core/pose.h"

namespace tessera::core {

using Trajectory = std::map<std::int64_t, core::Isometry>;  // timestamp ns -> T_W_C

// TUM format: "timestamp tx ty tz qx qy qz qw" per line, '#' comments. Throws core::Error
// naming the file and line.
Trajectory readTumTrajectory(const std::filesystem::path& path);

// One TUM-format line (with its newline) for the pose at `timestamp_ns`.
std::string tumLine(std::int64_t timestamp_ns, const core::Isometry& T_W_C);

// The pose at `t_ns`, interpolated between the poses around it (core::interpolate), or
// nothing when t_ns lies outside the trajectory or between poses more than max_gap_ns apart.
std::optional<core::Isometry> poseAt(const Trajectory& trajectory, std::int64_t t_ns,
                                     std::int64_t max_gap_ns);

// Writes TUM format (the inverse of readTumTrajectory). Throws core::Error naming the file.
void writeTumTrajectory(const Trajectory& trajectory, const std::filesystem::path& path);

struct AteResult {
  std::size_t pairs = 0;  // poses matched by timestamp
  double rmse_m = 0.0;
  double max_m = 0.0;
  core::Isometry T_gt_est = core::Isometry::Identity();  // aligns the estimate to the truth
};

// Matches each estimated pose to the ground-truth pose nearest in time within max_dt_ns.
// Returns nothing when fewer than 3 poses match.
std::optional<AteResult> absoluteTrajectoryError(const Trajectory& estimate,
                                                 const Trajectory& ground_truth,
                                                 std::int64_t max_dt_ns = 20'000'000);

}  // namespace tessera::core
