#include <sys/resource.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <numeric>

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

std::optional<double> percentile(std::vector<double> values, double p) {
  if (values.empty()) return std::nullopt;
  const auto rank = static_cast<std::size_t>(std::ceil(p * static_cast<double>(values.size())));
  const std::size_t k = std::clamp<std::size_t>(rank, 1, values.size()) - 1;
  std::nth_element(values.begin(), values.begin() + static_cast<long>(k), values.end());
  return values[k];
}

namespace {

StageFigures figures(const std::string& name, const StageTimer& timer) {
  return {name, timer.count(), timer.meanMs(), timer.medianMs(), timer.aloneFps()};
}

}  // namespace

RunSummary summariseRun(RunParts& parts, const RunOptions& options, double wall_s) {
  RunSummary summary;
  summary.source = parts.source.name();
  summary.frames = parts.sink.framesDone();
  summary.frames_bad = parts.source_stage.badFrames();
  summary.frames_integrated = parts.integration.framesIntegrated();
  summary.frames_without_pose = parts.integration.framesSkipped();
  summary.holdout_every = options.holdout_every;
  summary.frames_held_out = parts.integration.framesHeldOut();
  summary.frames_between_integrations = parts.integration.framesBetweenIntegrations();
  summary.poses = options.poses == PoseSource::kTrack ? "track" : "gt";
  summary.tracking_losses = parts.tracking.trackingLosses();
  summary.tracking_restarts = parts.tracking.trackingRestarts();
  summary.relocalisations = parts.tracking.relocalisations();
  summary.feature_poses = parts.tracking.featurePoses();
  summary.source_end_problem = parts.source_stage.endProblem();
  summary.stopped_on_request = parts.source_stage.stoppedOnRequest();
  summary.live = parts.source.isLive();
  summary.live_stats = parts.source_stage.liveStatsAtEnd();
  summary.source_interruptions = parts.sink.interruptions();
  summary.latency_ms_p50 = percentile(parts.sink.latenciesMs(), 0.50);
  summary.latency_ms_p95 = percentile(parts.sink.latenciesMs(), 0.95);
  summary.commit_latency_ms_p50 = percentile(parts.commit.commitLatenciesMs(), 0.50);
  summary.commit_latency_ms_p95 = percentile(parts.commit.commitLatenciesMs(), 0.95);
  summary.db_commit_ms_p50 = percentile(parts.commit.storeCommitMs(), 0.50);
  summary.db_commit_ms_p95 = percentile(parts.commit.storeCommitMs(), 0.95);
  if (parts.commit.matchTimer().count() > 0)
    summary.match_ms_p50 = parts.commit.matchTimer().medianMs();
  summary.wall_s = wall_s;
  summary.fps = wall_s > 0.0 ? static_cast<double>(summary.frames) / wall_s : 0.0;
  summary.ate = core::absoluteTrajectoryError(parts.sink.estimate(), parts.sink.groundTruth());
  if (parts.loop_closer) {
    parts.loop_closer->finish();
    const loop::LoopGraph& graph = parts.loop_closer->graph();
    summary.loop_closure = true;
    summary.loops = graph.stats();
    summary.loop_corrections_followed = parts.planes.correctionsFollowed();
    summary.loop_planes_moved = parts.planes.planesMovedByLoops();
    summary.loop_planes_merged = parts.planes.planesMergedByLoops();
    summary.loop_instances_retired = parts.commit.retirements();
    summary.loop_wait_s = parts.stages.loopWaitS();
    const core::Trajectory closed = graph.correct(parts.sink.estimate());
    core::writeTumTrajectory(closed, options.out_dir / "trajectory_closed.txt");
    summary.ate_after_closure = core::absoluteTrajectoryError(closed, parts.sink.groundTruth());
    spdlog::info("loop closure: {} keyframes, {} loops closed, {} rejected, pose graph {:.0f} ms",
                 summary.loops.keyframes, summary.loops.loop_closures, summary.loops.rejected(),
                 summary.loops.pose_graph_ms);
  }
  summary.tsdf_bytes = parts.integration.map().memoryBytes();
  summary.tsdf_blocks_released = parts.integration.blocksReleased();
  summary.stages = {figures("source", parts.source_stage.timer()),
                    figures("tracking", parts.tracking.timer()),
                    figures("integration", parts.integration.timer()),
                    figures("planes", parts.planes.timer()),
                    figures("textures", parts.bitmaps.timer()),
                    figures("match", parts.commit.matchTimer()),
                    figures("commit", parts.commit.timer()),
                    figures("sink", parts.sink.timer())};

  return summary;
}

}  // namespace internal

nlohmann::json reportJson(const RunSummary& summary) {
  using nlohmann::json;
  json report = {
      {"source", summary.source},
      {"frames", summary.frames},
      {"live", summary.live},
      // Replay never drops; a live device's frames that the busy pipeline never read do.
      {"frames_dropped", summary.live_stats.frames_dropped},
      {"frames_bad", summary.frames_bad},
      {"stopped_on_request", summary.stopped_on_request},
      {"frames_integrated", summary.frames_integrated},
      {"frames_without_pose", summary.frames_without_pose},
      {"holdout_every", summary.holdout_every},
      {"frames_held_out", summary.frames_held_out},
      {"frames_between_integrations", summary.frames_between_integrations},
      {"poses", summary.poses},
      {"tracking_losses", summary.tracking_losses},
      {"tracking_restarts", summary.tracking_restarts},
      {"relocalisations", summary.relocalisations},
      {"feature_poses", summary.feature_poses},
      {"wall_s", summary.wall_s},
      {"fps", summary.fps},
      {"peak_rss_mb", summary.peak_rss_mb},
      {"tsdf_bytes", summary.tsdf_bytes},
      {"tsdf_blocks_released", summary.tsdf_blocks_released},
      {"mesh_vertices", summary.mesh_vertices},
      {"map_triangles", summary.map_triangles},
      {"patches_finalized", summary.patches_finalized},
      {"patch_finalizations", summary.patch_finalizations},
      {"patches_retired", summary.patches_retired},
      {"colour_samples", summary.colour_samples},
      {"colour_sample_bytes", summary.colour_sample_bytes},
      {"samples_released", summary.samples_released},
      {"bitmaps", summary.bitmaps},
      {"bitmap_texels_observed", summary.bitmap_texels_observed},
      {"bitmap_texels_inpainted", summary.bitmap_texels_inpainted},
      {"bitmap_bytes", summary.bitmap_bytes},
      {"bitmap_ms_per_m2", summary.bitmap_ms_per_m2},
  };
  report["ate_m"] = summary.ate ? json(summary.ate->rmse_m) : json(nullptr);
  report["ate_max_m"] = summary.ate ? json(summary.ate->max_m) : json(nullptr);
  report["ate_pairs"] = summary.ate ? summary.ate->pairs : 0;
  report["loop_closure"] = summary.loop_closure;
  report["keyframes"] = summary.loops.keyframes;
  report["loop_closures"] = summary.loops.loop_closures;
  report["loop_closures_rejected"] = summary.loops.rejected();
  report["loop_candidates_checked"] = summary.loops.candidates_checked;
  report["loop_revisits_verified"] = summary.loops.revisits_verified;
  report["loops_rejected_as_drift"] = summary.loops.rejected_as_drift;
  report["loops_rejected_unconfirmed"] = summary.loops.rejected_unconfirmed;
  report["loops_rejected_by_graph"] = summary.loops.rejected_by_graph;
  report["pose_graph_optimisations"] = summary.loops.optimisations;
  report["pose_graph_ms"] = summary.loops.pose_graph_ms;
  report["loop_keyframe_ms"] = summary.loops.keyframe_ms;
  report["loop_corrections_followed"] = summary.loop_corrections_followed;
  report["loop_planes_moved"] = summary.loop_planes_moved;
  report["loop_planes_merged"] = summary.loop_planes_merged;
  report["loop_patches_retired_in_db"] = summary.loop_instances_retired;
  report["loop_wait_s"] = summary.loop_wait_s;
  report["ate_after_closure_m"] =
      summary.ate_after_closure ? json(summary.ate_after_closure->rmse_m) : json(nullptr);
  // View PSNR needs the captured frames again: `tessera eval RUN_DIR --frames SOURCE` fills it.
  for (const char* key : {"view_psnr_mean", "view_psnr_baseline_mean", "view_psnr_holdout_mean",
                          "view_psnr_baseline_holdout_mean", "view_pixels"}) {
    report[key] = nullptr;
  }
  const auto optional = [](const std::optional<double>& v) { return v ? json(*v) : json(nullptr); };
  report["frames_delivered"] =
      summary.live ? json(summary.live_stats.frames_delivered) : json(nullptr);
  report["drop_rate"] = summary.live && summary.live_stats.frames_delivered > 0
                            ? json(static_cast<double>(summary.live_stats.frames_dropped) /
                                   static_cast<double>(summary.live_stats.frames_delivered))
                            : json(nullptr);
  report["rss_growth_mb_per_1000_frames"] = optional(summary.rss_growth_mb_per_1000_frames);
  report["latency_ms_p50"] = optional(summary.latency_ms_p50);
  report["latency_ms_p95"] = optional(summary.latency_ms_p95);
  report["device_losses"] = summary.live_stats.device_losses;
  report["device_reconnects"] = summary.live_stats.reconnects;
  report["source_end_problem"] =
      summary.source_end_problem.empty() ? json(nullptr) : json(summary.source_end_problem);
  // The texture database: economy and matching (docs/METRICS.md).
  report["db"] = summary.db;
  report["db_run_id"] = summary.db_run_id;
  report["db_instances"] = summary.db_instances;
  if (const auto& link = summary.server_link) {
    report["db_server"] = {{"outages", link->outages},
                           {"disconnected_s", link->disconnected_s},
                           {"queued_commits", link->queued_commits},
                           {"replayed_commits", link->replayed_commits},
                           {"replayed_textures", link->replayed_textures},
                           {"refused_commits", link->refused_commits},
                           {"pending_commits", link->pending_commits},
                           {"journal", link->journal}};
  }
  report["textures_stored"] = summary.textures_stored;
  report["patterns_stored"] = summary.patterns_stored;
  report["textures_matched"] = summary.textures_matched;
  report["patterns_matched"] = summary.patterns_matched;
  report["overlays"] = summary.overlays;
  report["textured_patches"] = summary.textured_patches;
  report["reuses"] = summary.reuses;
  report["commit_failures"] = summary.commit_failures;
  report["reuse_rate"] = summary.textured_patches > 0
                             ? json(static_cast<double>(summary.reuses) /
                                    static_cast<double>(summary.textured_patches))
                             : json(nullptr);
  report["bytes_before"] = 3 * summary.pixels_before;
  report["bytes_after"] = 3 * summary.pixels_after;
  report["compression"] = summary.pixels_after > 0
                              ? json(static_cast<double>(summary.pixels_before) /
                                     static_cast<double>(summary.pixels_after))
                              : json(nullptr);
  std::vector<double> psnrs = summary.shown_psnrs_db;
  std::sort(psnrs.begin(), psnrs.end());
  report["patch_psnr_mean"] = psnrs.empty()
                                  ? json(nullptr)
                                  : json(std::accumulate(psnrs.begin(), psnrs.end(), 0.0) /
                                         static_cast<double>(psnrs.size()));
  report["patch_psnr_p5"] = optional(internal::percentile(psnrs, 0.05));
  report["patch_psnr_min"] = psnrs.empty() ? json(nullptr) : json(psnrs.front());
  report["patch_psnr_own"] = summary.textured_patches - psnrs.size();  // infinite: own bitmap
  report["ccv_considered"] = summary.ccv_considered;
  report["ccv_rejection"] = summary.ccv_considered > 0
                                ? json(static_cast<double>(summary.ccv_removed) /
                                       static_cast<double>(summary.ccv_considered))
                                : json(nullptr);
  report["commit_latency_ms_p50"] = optional(summary.commit_latency_ms_p50);
  report["commit_latency_ms_p95"] = optional(summary.commit_latency_ms_p95);
  report["db_commit_ms_p50"] = optional(summary.db_commit_ms_p50);
  report["db_commit_ms_p95"] = optional(summary.db_commit_ms_p95);
  report["match_ms_p50"] = optional(summary.match_ms_p50);
  // Against ground truth: `tessera eval` fills these.
  for (const char* key : {"plane_recall", "plane_precision", "false_match_rate",
                          "missed_match_rate", "economy", "gt_psnr_mean"}) {
    report[key] = nullptr;
  }
  json stages = json::object();
  for (const StageFigures& stage : summary.stages) {
    stages[stage.name] = {{"calls", stage.calls},
                          {"mean_ms", stage.mean_ms},
                          {"median_ms", stage.median_ms},
                          {"alone_fps", stage.alone_fps}};
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
