#include "tessera/pipeline/run.h"

#include <sys/resource.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <fstream>
#include <numeric>
#include <set>

#include <fmt/format.h>
#include <spdlog/spdlog.h>
#include <nlohmann/json.hpp>

#include "tessera/core/error.h"
#include "tessera/db/texture_store.h"
#include "tessera/map_export/map_files.h"
#include "tessera/map_export/patch_files.h"
#include "tessera/pipeline/flow_graph.h"
#include "tessera/pipeline/texture_db_stages.h"
#include "tessera/texture/bitmap_export.h"

namespace tessera::pipeline {

double peakRssMb() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return static_cast<double>(usage.ru_maxrss) / 1024.0;  // ru_maxrss is in KiB on Linux
}

namespace {

StageFigures figures(const std::string& name, const StageTimer& timer) {
  return {name, timer.count(), timer.meanMs(), timer.medianMs(), timer.aloneFps()};
}

void createOutputDir(const std::filesystem::path& dir) {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec || !std::filesystem::is_directory(dir)) {
    throw core::Error(fmt::format("{}: cannot create the output folder: {}", dir.string(),
                                  ec ? ec.message() : "a file of that name exists"));
  }
}

// The p-quantile (nearest rank) of `values`; nothing when there are none.
std::optional<double> percentile(std::vector<double> values, double p) {
  if (values.empty()) return std::nullopt;
  const auto rank = static_cast<std::size_t>(std::ceil(p * static_cast<double>(values.size())));
  const std::size_t k = std::clamp<std::size_t>(rank, 1, values.size()) - 1;
  std::nth_element(values.begin(), values.begin() + static_cast<long>(k), values.end());
  return values[k];
}

void removeDatabaseFiles(const std::filesystem::path& path) {
  for (const char* suffix : {"", "-wal", "-shm", "-journal"}) {
    std::error_code ec;
    std::filesystem::remove(path.string() + suffix, ec);
  }
}

// Gives each exported patch the database texture its newest instance names, writes each such
// texture once (OUT/textures/texture_<id>.png), and fills the summary's economy figures.
void bindMapTextures(const db::TextureStore& store, const CommitStage& commits,
                     const reuse::StoreCatalog& catalog, const std::filesystem::path& out_dir,
                     planes::TextureBindings& bindings, RunSummary& summary) {
  std::set<std::int64_t> used;
  // One layer as the map shows it; each database texture is written (and counted) once.
  const auto show = [&](const db::TextureInstance& instance, const match::StoredTexture& stored) {
    const cv::Mat& rgb = stored.storedRgb();
    planes::MapTexture shown;
    shown.texture_id = store.resolvedId(instance.texture_id);  // the server's id, once sent
    shown.image = fmt::format("textures/texture_{}.png", shown.texture_id);
    shown.width = rgb.cols;
    shown.height = rgb.rows;
    shown.transform = instance.transform;
    shown.tiled = stored.pattern;
    if (stored.pattern) shown.lattice = stored.lattice;
    shown.reused = instance.reused;
    shown.psnr_db = instance.psnr_db;
    if (instance.reused)
      (stored.pattern ? summary.patterns_matched : summary.textures_matched) += 1;
    if (used.insert(shown.texture_id).second) {
      texture::writeRgbaPng(out_dir / shown.image, rgb, stored.storedMask());
      summary.pixels_after += rgb.total();
    }
    return shown;
  };
  for (auto& [patch_id, binding] : bindings) {
    summary.pixels_before += static_cast<std::size_t>(binding.width) * binding.height;
    const auto it = commits.instances().find(patch_id);
    const bool current = it != commits.instances().end() && !it->second.empty() &&
                         it->second.front().version == binding.version;
    std::vector<std::shared_ptr<const match::StoredTexture>> layers;
    if (current) {
      for (const db::TextureInstance& instance : it->second) {
        layers.push_back(catalog.load(instance.texture_id));
        if (!layers.back()) layers.clear();
        if (layers.empty()) break;
      }
    }
    if (layers.empty()) {  // not committed: the map shows the patch's own bitmap
      summary.pixels_after += static_cast<std::size_t>(binding.width) * binding.height;
      continue;
    }
    const db::TextureInstance& instance = it->second.front();
    binding.map_texture = show(instance, *layers.front());
    for (std::size_t i = 1; i < layers.size(); ++i) {
      binding.overlays.push_back(show(it->second[i], *layers[i]));
    }
    summary.overlays += layers.size() - 1;
    summary.textured_patches += 1;
    summary.reuses += instance.reused ? 1 : 0;
    // A reuse or a pattern shows the patch through another image: its fidelity counts.
    if (instance.psnr_db) summary.shown_psnrs_db.push_back(*instance.psnr_db);
  }
  summary.textures_stored = commits.texturesStored();
  summary.patterns_stored = commits.patternsStored();
  summary.commit_failures = commits.commitFailures();
  summary.ccv_considered = commits.ccvConsidered();
  summary.ccv_removed = commits.ccvRemoved();
}

}  // namespace

RunSummary runPipeline(core::FrameSource& source, const RunConfig& config,
                       const RunOptions& options) {
  createOutputDir(options.out_dir);
  const int threads = options.threads > 0 ? options.threads : defaultThreadCount();

  std::optional<std::size_t> total = source.frameCount();
  if (total && options.max_frames) total = std::min(*total, *options.max_frames);

  SourceStage source_stage(source, options.max_frames, options.stop);
  // Loop closure runs on its own thread, fed with the tracker's keyframes.
  std::unique_ptr<loop::LoopCloser> loop_closer;
  if (config.loop_closure.enabled && options.poses == PoseSource::kTrack) {
    loop_closer = std::make_unique<loop::LoopCloser>(config.loop_closure);
  }
  TrackingStage tracking_stage(config.tracker, options.poses, loop_closer.get());
  IntegrationStage integration_stage(config.tsdf, threads, options.holdout_every);
  planes::PlaneAlignmentConfig alignment = config.pose_correction;
  alignment.enabled = alignment.enabled && options.poses == PoseSource::kTrack;
  PlaneStage plane_stage(config.planes, config.patches, alignment, loop_closer.get());
  // Finalized patches' colour samples wait here while out of memory; removed at the end.
  const std::filesystem::path sample_dir = options.out_dir / "samples";
  plane_stage.spillSamplesTo(sample_dir);
  TextureStage texture_stage(config.textures, options.out_dir);
  StatsSink sink(options.out_dir, total, options.on_progress,
                 [&texture_stage] { return texture_stage.bitmapBytes(); });
  if (options.monitor != nullptr) {
    sink.attachMonitor(options.monitor,
                       [&source_stage] { return source_stage.framesDroppedSoFar(); });
    options.monitor->start(source.name());
  }
  // Without --db the run starts its own database, replacing one an earlier run left in OUT.
  const std::string db_location =
      options.db ? *options.db : (options.out_dir / "textures.db").string();
  if (!options.db) removeDatabaseFiles(db_location);
  db::OpenOptions db_options;
  db_options.journal = options.out_dir / "db_journal.sqlite";  // a server's database only
  const std::unique_ptr<db::TextureStore> store = db::openTextureStore(db_location, db_options);
  const std::int64_t run_id = store->beginRun(source.name());
  reuse::StoreCatalog catalog(*store, config.match);
  const DescribeStage describe_stage(texture_stage, config.match, config.pattern);
  CommitStage commit_stage(*store, catalog, {config.match, config.pattern, run_id});

  const auto start = std::chrono::steady_clock::now();
  runGraph(source_stage, tracking_stage, integration_stage, plane_stage, texture_stage,
           describe_stage, commit_stage, sink,
           {threads, source.isLive() ? config.pipeline.live_frames_in_flight
                                     : config.pipeline.max_frames_in_flight});
  store->finishRun(run_id);  // a server's store first sends what waited in its journal
  const double wall_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();

  RunSummary summary;
  summary.source = source.name();
  summary.frames = sink.framesDone();
  summary.frames_bad = source_stage.badFrames();
  summary.frames_integrated = integration_stage.framesIntegrated();
  summary.frames_without_pose = integration_stage.framesSkipped();
  summary.holdout_every = options.holdout_every;
  summary.frames_held_out = integration_stage.framesHeldOut();
  summary.frames_between_integrations = integration_stage.framesBetweenIntegrations();
  summary.poses = options.poses == PoseSource::kTrack ? "track" : "gt";
  summary.tracking_losses = tracking_stage.trackingLosses();
  summary.tracking_restarts = tracking_stage.trackingRestarts();
  summary.relocalisations = tracking_stage.relocalisations();
  summary.feature_poses = tracking_stage.featurePoses();
  summary.source_end_problem = source_stage.endProblem();
  summary.stopped_on_request = source_stage.stoppedOnRequest();
  summary.live = source.isLive();
  summary.live_stats = source_stage.liveStatsAtEnd();
  summary.source_interruptions = sink.interruptions();
  summary.latency_ms_p50 = percentile(sink.latenciesMs(), 0.50);
  summary.latency_ms_p95 = percentile(sink.latenciesMs(), 0.95);
  summary.commit_latency_ms_p50 = percentile(commit_stage.commitLatenciesMs(), 0.50);
  summary.commit_latency_ms_p95 = percentile(commit_stage.commitLatenciesMs(), 0.95);
  summary.db_commit_ms_p50 = percentile(commit_stage.storeCommitMs(), 0.50);
  summary.db_commit_ms_p95 = percentile(commit_stage.storeCommitMs(), 0.95);
  if (commit_stage.matchTimer().count() > 0)
    summary.match_ms_p50 = commit_stage.matchTimer().medianMs();
  summary.wall_s = wall_s;
  summary.fps = wall_s > 0.0 ? static_cast<double>(summary.frames) / wall_s : 0.0;
  summary.ate = core::absoluteTrajectoryError(sink.estimate(), sink.groundTruth());
  if (loop_closer) {
    loop_closer->finish();
    const loop::LoopGraph& graph = loop_closer->graph();
    summary.loop_closure = true;
    summary.loops = graph.stats();
    summary.loop_corrections_followed = plane_stage.correctionsFollowed();
    summary.loop_planes_moved = plane_stage.planesMovedByLoops();
    summary.loop_planes_merged = plane_stage.planesMergedByLoops();
    summary.loop_instances_retired = commit_stage.retirements();
    summary.loop_wait_s = plane_stage.loopWaitS();
    const core::Trajectory closed = graph.correct(sink.estimate());
    core::writeTumTrajectory(closed, options.out_dir / "trajectory_closed.txt");
    summary.ate_after_closure = core::absoluteTrajectoryError(closed, sink.groundTruth());
    spdlog::info("loop closure: {} keyframes, {} loops closed, {} rejected, pose graph {:.0f} ms",
                 summary.loops.keyframes, summary.loops.loop_closures, summary.loops.rejected(),
                 summary.loops.pose_graph_ms);
  }
  summary.tsdf_bytes = integration_stage.map().memoryBytes();
  summary.tsdf_blocks_released = integration_stage.blocksReleased();
  summary.stages = {figures("source", source_stage.timer()),
                    figures("tracking", tracking_stage.timer()),
                    figures("integration", integration_stage.timer()),
                    figures("planes", plane_stage.timer()),
                    figures("textures", texture_stage.timer()),
                    figures("match", commit_stage.matchTimer()),
                    figures("commit", commit_stage.timer()),
                    figures("sink", sink.timer())};

  // Export: the mesh is written even when the source ended abnormally, so work is kept.
  const auto mesh = integration_stage.map().extractMesh();
  summary.mesh_vertices = mesh.vertices.size();
  fusion::writePly(mesh, options.out_dir / "mesh.ply");
  const planes::PatchMap& patches = plane_stage.map();
  summary.patches_finalized = patches.finalizedCount();
  summary.patch_finalizations = plane_stage.finalizations();
  summary.patches_retired = plane_stage.retirements();
  for (const planes::Patch& patch : patches.patches()) {
    summary.colour_samples += patch.samples.size();
    summary.colour_sample_bytes += patch.samples.bytes();
  }
  summary.samples_released = patches.samplesReleased();
  std::error_code ignored;
  std::filesystem::remove_all(sample_dir, ignored);
  texture_stage.flush();
  planes::TextureBindings textures =
      texture::currentBindings(texture_stage.written(), patches, options.out_dir);
  summary.db = store->location();
  summary.server_link = store->serverLink();
  summary.db_run_id = run_id;
  for (const auto& [patch, layers] : commit_stage.instances()) summary.db_instances += layers.size();
  bindMapTextures(*store, commit_stage, catalog, options.out_dir, textures, summary);
  for (const auto& [id, binding] : textures) {
    summary.bitmaps += 1;
    summary.bitmap_texels_observed += binding.observed;
    summary.bitmap_texels_inpainted += binding.inpainted;
    summary.bitmap_bytes += 3 * static_cast<std::size_t>(binding.width) * binding.height;
  }
  if (texture_stage.areaBuiltM2() > 0.0) {
    summary.bitmap_ms_per_m2 = texture_stage.timer().totalMs() / texture_stage.areaBuiltM2();
  }
  map_export::writePatchesObj(patches, options.out_dir / "patches.obj", textures);
  // The map users open: patches triangulated with their holes, one material per texture.
  const map_export::MapModel map_model =
      map_export::buildMapModel(patches, textures, options.residual ? &mesh : nullptr);
  map_export::writeMapObj(map_model, options.out_dir / "map.obj");
  map_export::writeMapGlb(map_model, options.out_dir, options.out_dir / "map.glb");
  summary.map_triangles = map_model.triangleCount();
  map_export::writePatchesJson(patches, options.out_dir / "patches.json", textures);
  summary.peak_rss_mb = peakRssMb();
  summary.rss_growth_mb_per_1000_frames = sink.rssGrowthMbPer1000Frames();
  writeReport(summary, options.out_dir / "report.json");
  if (options.monitor != nullptr) options.monitor->finish(reportJson(summary));
  return summary;
}

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
  report["patch_psnr_p5"] = optional(percentile(psnrs, 0.05));
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
