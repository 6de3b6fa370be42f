#include "tessera/core/trajectory.h"

#include <cmath>
#include <fstream>
#include <sstream>

#include <fmt/format.h>
#include <Eigen/Geometry>

#include "tessera/core/error.h"

namespace tessera::core {

Trajectory readTumTrajectory(const std::filesystem::path& path) {
  std::ifstream in(path);
  if (!in) throw core::Error(fmt::format("{}: cannot open the trajectory", path.string()));
  Trajectory trajectory;
  std::string line;
  for (int number = 1; std::getline(in, line); ++number) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream fields(line);
    double t, tx, ty, tz, qx, qy, qz, qw;
    if (!(fields >> t >> tx >> ty >> tz >> qx >> qy >> qz >> qw)) {
      throw core::Error(
          fmt::format("{}:{}: expected 'timestamp tx ty tz qx qy qz qw'", path.string(), number));
    }
    trajectory[std::llround(t * 1e9)] =
        core::isometryFromTranslationQuaternion({tx, ty, tz}, qx, qy, qz, qw);
  }
  return trajectory;
}

std::string tumLine(std::int64_t timestamp_ns, const core::Isometry& T_W_C) {
  const Eigen::Quaterniond q(T_W_C.rotation());
  const Eigen::Vector3d p = T_W_C.translation();
  return fmt::format("{}.{:09d} {:.6f} {:.6f} {:.6f} {:.9f} {:.9f} {:.9f} {:.9f}\n",
                     timestamp_ns / 1'000'000'000, timestamp_ns % 1'000'000'000, p.x(), p.y(),
                     p.z(), q.x(), q.y(), q.z(), q.w());
}

std::optional<core::Isometry> poseAt(const Trajectory& trajectory, std::int64_t t_ns,
                                     std::int64_t max_gap_ns) {
  const auto after = trajectory.lower_bound(t_ns);
  if (after == trajectory.end()) return std::nullopt;
  if (after->first == t_ns) return after->second;
  if (after == trajectory.begin()) return std::nullopt;
  const auto before = std::prev(after);
  const std::int64_t gap = after->first - before->first;
  if (gap > max_gap_ns) return std::nullopt;
  const double alpha = static_cast<double>(t_ns - before->first) / static_cast<double>(gap);
  return core::interpolate(before->second, after->second, alpha);
}

void writeTumTrajectory(const Trajectory& trajectory, const std::filesystem::path& path) {
  std::ofstream out(path);
  out << "# timestamp tx ty tz qx qy qz qw\n";
  for (const auto& [t, pose] : trajectory) out << tumLine(t, pose);
  out.close();
  if (!out) throw core::Error(fmt::format("{}: cannot write the trajectory", path.string()));
}

std::optional<AteResult> absoluteTrajectoryError(const Trajectory& estimate,
                                                 const Trajectory& ground_truth,
                                                 std::int64_t max_dt_ns) {
  std::vector<Eigen::Vector3d> est, gt;
  for (const auto& [t, pose] : estimate) {
    auto after = ground_truth.lower_bound(t);
    auto best = ground_truth.end();
    if (after != ground_truth.end()) best = after;
    if (after != ground_truth.begin()) {
      const auto before = std::prev(after);
      if (best == ground_truth.end() || t - before->first < best->first - t) best = before;
    }
    if (best == ground_truth.end() || std::llabs(best->first - t) > max_dt_ns) continue;
    est.push_back(pose.translation());
    gt.push_back(best->second.translation());
  }
  if (est.size() < 3) return std::nullopt;

  Eigen::Matrix3Xd from(3, static_cast<Eigen::Index>(est.size()));
  Eigen::Matrix3Xd to(3, static_cast<Eigen::Index>(gt.size()));
  for (std::size_t i = 0; i < est.size(); ++i) {
    from.col(static_cast<Eigen::Index>(i)) = est[i];
    to.col(static_cast<Eigen::Index>(i)) = gt[i];
  }
  AteResult result;
  result.pairs = est.size();
  result.T_gt_est = core::Isometry(Eigen::umeyama(from, to, /*with_scaling=*/false));
  double sum = 0.0;
  for (std::size_t i = 0; i < est.size(); ++i) {
    const double error = (result.T_gt_est * est[i] - gt[i]).norm();
    sum += error * error;
    result.max_m = std::max(result.max_m, error);
  }
  result.rmse_m = std::sqrt(sum / static_cast<double>(est.size()));
  return result;
}

}  // namespace tessera::core
