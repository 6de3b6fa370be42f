#include <sys/resource.h>

#include <fstream>

#include <fmt/format.h>
#include <spdlog/spdlog.h>
#include <nlohmann/json.hpp>

#include "internal/run_parts.h"
#include "tessera/core/error.h"
#include "tessera/core/trajectory.h"

namespace tessera::pipeline {

double peakRssMb() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return static_cast<double>(usage.ru_maxrss) / 1024.0;  // ru_maxrss is in KiB on Linux
}

namespace internal {

namespace {

StageFigures figures(const std::string& name, const StageTimer& timer) {
  return {
      name, timer.count(), timer.meanMs(), timer.medianMs(), timer.aloneFps(), timer.cpuMeanMs()};
}

}  // namespace

RunSummary summariseRun(RunParts& parts, const RunOptions& options, double wall_s) {
  RunSummary summary;
  summary.source = parts.source.name();
  summary.wall_s = wall_s;
  summary.stream = parts.sink.figures();
  summary.fps = wall_s > 0.0 ? static_cast<double>(summary.stream.frames) / wall_s : 0.0;
  summary.input = parts.source_stage.figures();
  summary.tracking = parts.tracking.figures();
  summary.integration = parts.integration.figures();
  summary.patches = parts.planes.figures();
  summary.commits = parts.commit.figures();
  summary.ate = core::absoluteTrajectoryError(parts.sink.estimate(), parts.sink.groundTruth());
  if (parts.loop_closer) {
    parts.loop_closer->finish();
    const loop::LoopGraph& graph = parts.loop_closer->graph();
    LoopFigures& loops = summary.loops;
    loops.enabled = true;
    loops.loops = graph.stats();
    loops.instances_retired = summary.commits.retirements;
    loops.wait_s = parts.stages.loopWaitS();
    const core::Trajectory closed = graph.correct(parts.sink.estimate());
    core::writeTumTrajectory(closed, options.out_dir / "trajectory_closed.txt");
    loops.poses_apart = parts.sink.estimate().size() - closed.size();
    loops.ate_after_closure = core::absoluteTrajectoryError(closed, parts.sink.groundTruth());
    spdlog::info("loop closure: {} keyframes, {} loops closed, {} rejected, pose graph {:.0f} ms",
                 loops.loops.keyframes, loops.loops.loop_closures, loops.loops.rejected(),
                 loops.loops.pose_graph_ms);
    if (loops.loops.segments > 1) {
      spdlog::info(
          "tracking segments: {}, {} joined; {} poses of segments never joined to the first are "
          "left out of trajectory_closed.txt",
          loops.loops.segments, loops.loops.segments_joined, loops.poses_apart);
    }
    if (loops.ate_after_closure) {
      spdlog::info("ATE after loop closure: {:.1f} mm RMSE over {} poses",
                   loops.ate_after_closure->rmse_m * 1e3, loops.ate_after_closure->pairs);
    }
  }
  summary.stages = {figures("source", parts.source_stage.timer()),
                    figures("tracking", parts.tracking.timer()),
                    figures("integration", parts.integration.timer()),
                    figures("planes", parts.planes.timer()),
                    figures("textures", parts.bitmaps.timer()),
                    figures("describe", summary.commits.describe),
                    figures("match", summary.commits.match),
                    figures("commit", parts.commit.timer()),
                    figures("sink", parts.sink.timer())};
  return summary;
}

}  // namespace internal

nlohmann::json reportJson(const RunSummary& summary) {
  using nlohmann::json;
  json report = {
      {"source", summary.source},
      {"wall_s", summary.wall_s},
      {"fps", summary.fps},
      {"end_to_end_s", summary.end_to_end_s},
      {"fps_end_to_end", summary.end_to_end_s > 0.0
                             ? static_cast<double>(summary.stream.frames) / summary.end_to_end_s
                             : 0.0},
      {"peak_rss_mb", summary.peak_rss_mb}};
  summary.stream.addTo(report);
  summary.cpu.addTo(report);
  summary.input.addTo(report);
  summary.tracking.addTo(report);
  summary.integration.addTo(report);
  summary.patches.addTo(report);
  summary.bitmaps.addTo(report);
  summary.commits.addTo(report);
  addEconomy(summary.economy, report);
  summary.database.addTo(report);
  summary.loops.addTo(report);
  summary.exported.addTo(report);
  report["ate_m"] = summary.ate ? json(summary.ate->rmse_m) : json(nullptr);
  report["ate_max_m"] = summary.ate ? json(summary.ate->max_m) : json(nullptr);
  report["ate_pairs"] = summary.ate ? summary.ate->pairs : 0;
  // Figures that need the captured frames again or ground truth: `tessera eval RUN_DIR` fills
  // them.
  for (const char* key :
       {"view_psnr_mean", "view_psnr_baseline_mean", "view_psnr_holdout_mean",
        "view_psnr_baseline_holdout_mean", "view_ssim_mean", "view_ssim_baseline_mean",
        "view_ssim_holdout_mean", "view_ssim_baseline_holdout_mean", "view_detail_mean",
        "view_detail_baseline_mean", "view_detail_holdout_mean",
        "view_detail_baseline_holdout_mean", "view_pixels", "plane_recall", "plane_precision",
        "false_match_rate", "missed_match_rate", "economy", "gt_psnr_mean"}) {
    report[key] = nullptr;
  }
  json stages = json::object();
  for (const StageFigures& stage : summary.stages) {
    stages[stage.name] = {{"calls", stage.calls},
                          {"mean_ms", stage.mean_ms},
                          {"median_ms", stage.median_ms},
                          {"alone_fps", stage.alone_fps},
                          {"cpu_ms_mean", stage.cpu_ms_mean}};
  }
  report["stages"] = stages;
  return report;
}

void writeReport(const RunSummary& summary, const std::filesystem::path& path) {
  std::ofstream out(path);
  out << reportJson(summary).dump(2) << '\n';
  out.close();
  if (!out) {
    throw core::Error(fmt::format("{}: could not write the report (disk full?)", path.string()));
  }
}

}  // namespace tessera::pipeline
