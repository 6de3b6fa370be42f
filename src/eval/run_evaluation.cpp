#include "tessera/eval/run_evaluation.h"

#include <fstream>

#include <fmt/format.h>

#include "tessera/core/error.h"
#include "tessera/eval/trajectory.h"

namespace tessera::eval {

namespace {

nlohmann::json readJson(const std::filesystem::path& path) {
  std::ifstream in(path);
  if (!in) throw core::Error(fmt::format("{}: cannot open", path.string()));
  nlohmann::json json = nlohmann::json::parse(in, nullptr, /*allow_exceptions=*/false);
  if (json.is_discarded()) throw core::Error(fmt::format("{}: not valid JSON", path.string()));
  return json;
}

Trajectory groundTruthTrajectory(const nlohmann::json& gt) {
  Trajectory trajectory;
  for (const auto& frame : gt.value("frames", nlohmann::json::array())) {
    if (!frame.contains("T_W_C")) continue;
    const auto p = frame["T_W_C"].get<std::vector<double>>();
    if (p.size() != 7) continue;
    trajectory[frame["timestamp_ns"].get<std::int64_t>()] = core::isometryFromTranslationQuaternion(
        Eigen::Vector3d(p[0], p[1], p[2]), p[3], p[4], p[5], p[6]);
  }
  return trajectory;
}

}  // namespace

nlohmann::json evaluateRun(const std::filesystem::path& run_dir,
                           const std::filesystem::path& ground_truth) {
  const auto report_path = run_dir / "report.json";
  nlohmann::json report = readJson(report_path);
  const nlohmann::json gt = readJson(ground_truth);

  nlohmann::json figures = {{"ate_m", nullptr}, {"ate_max_m", nullptr}, {"ate_pairs", 0}};
  const auto trajectory_path = run_dir / "trajectory.txt";
  if (std::filesystem::exists(trajectory_path)) {
    const Trajectory estimate = readTumTrajectory(trajectory_path);
    if (const auto ate = absoluteTrajectoryError(estimate, groundTruthTrajectory(gt))) {
      figures["ate_m"] = ate->rmse_m;
      figures["ate_max_m"] = ate->max_m;
      figures["ate_pairs"] = ate->pairs;
      Trajectory aligned;
      for (const auto& [t, pose] : estimate) aligned[t] = ate->T_gt_est * pose;
      writeTumTrajectory(aligned, run_dir / "trajectory_aligned.txt");
    }
  }
  // Figures of stages that do not exist yet stay null (docs/METRICS.md).
  for (const char* key : {"plane_recall", "plane_precision", "false_match_rate",
                          "missed_match_rate", "economy", "gt_psnr_mean"}) {
    figures[key] = nullptr;
  }
  figures["ground_truth"] = ground_truth.string();
  for (const auto& [key, value] : figures.items()) report[key] = value;

  std::ofstream out(report_path);
  out << report.dump(2) << '\n';
  out.close();
  if (!out) throw core::Error(fmt::format("{}: cannot write (disk full?)", report_path.string()));
  return figures;
}

}  // namespace tessera::eval
