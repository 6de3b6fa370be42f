#include "run_command.h"

#include <memory>

#include <fmt/format.h>
#include <spdlog/spdlog.h>
#include <opencv2/core/utility.hpp>

#include "progress_line.h"
#include "ros_publishing.h"
#include "source_factory.h"
#include "stop_request.h"
#include "tessera/core/error.h"
#include "tessera/monitor/monitor_server.h"
#include "tessera/pipeline/flow_graph.h"
#include "tessera/pipeline/run.h"

namespace tessera::cli {

CLI::App* addRunCommand(CLI::App& app, RunArguments& args) {
  CLI::App* run = app.add_subcommand(
      "run", "Build a map from SOURCE and write it, with report.json and stats.jsonl, to --out");
  run->add_option(
      "SOURCE", args.source,
      "OpenNI2 recording (.oni), ROS 1 bag (.bag), recorded dataset folder (TUM RGB-D, "
      "7-Scenes, Redwood, slambook), synthetic scene (.yaml), live device (openni2://, "
      "openni2://URI, freenect://N, v4l2:///dev/videoN?depth=/dev/videoM; docs/ROBOT.md) or a "
      "ROS 1 graph (ros://[HOST:PORT]; docs/ROS.md). Default: recordings/office.oni (rendered by "
      "the build)");
  run->add_option("--config", args.config, "YAML config (keys as in config/default.yaml)")
      ->check(CLI::ExistingFile);
  run->add_option("--out", args.out_dir, "Output folder (created if needed)")
      ->capture_default_str();
  run->add_option("--threads", args.threads,
                  "Worker threads for the flow graph, Open3D and OpenCV (0: all cores)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  run->add_option("--poses", args.poses,
                  "track: estimate camera poses (RGB-D odometry); gt: use the recording's "
                  "ground truth")
      ->check(CLI::IsMember({"track", "gt"}))
      ->capture_default_str();
  run->add_option("--holdout-every", args.holdout_every,
                  "Leave every N-th frame out of fusion and texturing (it is still posed), so "
                  "that `tessera eval --frames` scores views the map was not built from (0: none)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  run->add_flag("--residual", args.residual,
                "Also put the non-planar rest of the TSDF surface (what no patch covers), "
                "vertex-coloured, into map.obj and map.glb as the object 'residual'");
  run->add_option("--db", args.db,
                  "Texture database to match against and grow: a SQLite file (created if "
                  "missing) or postgresql://USER@HOST[:PORT]/DBNAME (password from PGPASSWORD or "
                  "~/.pgpass); give the same one to several runs to reuse its textures. "
                  "Default: OUT/textures.db");
  run->add_option("--record", args.source_args.record_path,
                  "Live devices: also record what the device sends to this .oni file "
                  "(OpenNI2's Recorder, lossless; replays with `tessera run FILE`)");
  run->add_option("--monitor", args.monitor,
                  "Serve the run's figures over HTTP on [ADDR:]PORT (ADDR 127.0.0.1 unless "
                  "given; PORT 0 picks a free one): / (live page), /metrics (Prometheus), /stats "
                  "(JSON), /events (server-sent events), /textures (docs/MONITOR.md)");
  run->add_option("--monitor-token", args.monitor_token,
                  "Require this bearer token on every monitor request (also read from "
                  "TESSERA_MONITOR_TOKEN, which keeps it out of the process list)")
      ->envname("TESSERA_MONITOR_TOKEN");
  run->add_option("--publish", args.publish,
                  "Publish the map on a ROS 1 graph, ros://[HOST:PORT] (docs/ROS.md: pose on "
                  "/tf, patches as RViz markers, figures on /diagnostics, exported files), or "
                  "none. Default: a ros:// SOURCE publishes to its own graph");
  run->add_option("--map-frame", args.map_frame, "--publish: the tf frame of the map")
      ->capture_default_str();
  run->add_option("--tf-camera-frame", args.published_camera_frame,
                  "--publish: the tf frame tessera moves with the camera pose (map -> it)")
      ->capture_default_str();
  run->add_option("--skip-frames", args.skip_frames,
                  "Start at SOURCE's frame N: the N frames before it, readable or not, are "
                  "skipped (a recording replayed from the middle; with --max-frames, a range "
                  "of it)")
      ->capture_default_str();
  run->add_option("--continue", args.continue_dir,
                  "Continue the map saved in this run folder (OUT/map, written at the end of "
                  "every run): its first frames are relocalised in it, surfaces seen again grow "
                  "its patches, its database is reused, and the merged map is written back to "
                  "it (it becomes OUT)");
  run->add_flag("--no-save-map", args.no_save_map,
                "Do not write OUT/map (the state --continue needs: keyframes, patches, colour "
                "samples)");
  run->add_flag("--quiet", args.quiet,
                "No progress line on a terminal, nor periodic progress lines in a log");
  addSourceOptions(*run, args.source_args);
  return run;
}

int runCommand(const RunArguments& args) {
  try {
    const pipeline::RunConfig config = pipeline::loadRunConfig(
        args.config.empty() ? std::nullopt : std::optional<std::filesystem::path>(args.config));

    if (!args.continue_dir.empty() && args.out_dir != RunArguments{}.out_dir &&
        std::filesystem::path(args.out_dir) != std::filesystem::path(args.continue_dir)) {
      throw core::ConfigError(
          fmt::format("--continue {} writes the merged map back to that folder: leave out --out {}",
                      args.continue_dir, args.out_dir));
    }
    const std::string out_dir = args.continue_dir.empty() ? args.out_dir : args.continue_dir;
    const std::string source_spec = args.source.empty() ? defaultRecording().string() : args.source;
    if (args.source.empty()) spdlog::info("no SOURCE given: replaying {}", source_spec);
    auto source = openSource(source_spec, args.source_args);

    const int threads = args.threads > 0 ? args.threads : pipeline::defaultThreadCount();
    cv::setNumThreads(threads);
    pipeline::MapMonitor monitor;
    ProgressLine progress(&monitor, args.quiet);
    std::unique_ptr<monitor::MonitorServer> server;
    if (!args.monitor.empty()) {
      monitor::MonitorServerOptions server_options;
      server_options.listen = monitor::parseListenAddress(args.monitor);
      server_options.token = args.monitor_token;
      server_options.db =
          args.db.empty() ? (std::filesystem::path(out_dir) / "textures.db").string() : args.db;
      server = std::make_unique<monitor::MonitorServer>(monitor, server_options);
      spdlog::info("monitor: {}{}", server->url(),
                   args.monitor_token.empty() ? "" : " (bearer token required)");
    }
    const std::unique_ptr<pipeline::RunListener> publisher =
        openMapPublisher(args, source_spec, monitor);
    pipeline::RunOptions run_options;
    run_options.monitor = &monitor;
    run_options.listener = publisher.get();
    run_options.out_dir = out_dir;
    run_options.skip_frames = args.skip_frames;
    run_options.continue_map = !args.continue_dir.empty();
    run_options.save_map = !args.no_save_map;
    run_options.threads = threads;
    run_options.poses =
        args.poses == "gt" ? pipeline::PoseSource::kGroundTruth : pipeline::PoseSource::kTrack;
    run_options.holdout_every = args.holdout_every;
    run_options.residual = args.residual;
    if (!args.db.empty()) run_options.db = args.db;
    if (args.source_args.max_frames > 0) run_options.max_frames = args.source_args.max_frames;
    run_options.on_progress = [&progress](const pipeline::Progress& p) { progress.update(p); };
    // Live or replay: Ctrl-C stops the input and the map is finished and exported.
    run_options.stop = &stopOnInterrupt();

    const pipeline::RunSummary summary = pipeline::runPipeline(*source, config, run_options);
    progress.finish();
    spdlog::info(
        "{} frames in {:.2f} s ({:.1f} frames/s), {} integrated, {} between integrations, {} bad, "
        "{} without pose{}",
        summary.stream.frames, summary.wall_s, summary.fps, summary.integration.frames_integrated,
        summary.integration.frames_between_integrations, summary.input.frames_bad,
        summary.integration.frames_without_pose,
        summary.integration.frames_held_apart > 0
            ? fmt::format(", {} held apart (tracked in a segment not joined to the map)",
                          summary.integration.frames_held_apart)
            : std::string());
    if (summary.tracking.poses == "track") {
      spdlog::info(
          "tracking: {} frames lost, {} relocalised, {} restarts, {} posed from features first",
          summary.tracking.tracking_losses, summary.tracking.relocalisations,
          summary.tracking.tracking_restarts, summary.tracking.feature_poses);
    }
    if (summary.input.live) {
      const core::LiveStats& live = summary.input.live_stats;
      spdlog::info(
          "live: {} frames sent, {} dropped ({:.1f} %), latency p50 {:.0f} ms, p95 {:.0f} "
          "ms; {} device losses, {} reconnects",
          live.frames_delivered, live.frames_dropped,
          live.frames_delivered > 0 ? 100.0 * static_cast<double>(live.frames_dropped) /
                                          static_cast<double>(live.frames_delivered)
                                    : 0.0,
          summary.stream.latency_ms_p50.value_or(0.0), summary.stream.latency_ms_p95.value_or(0.0),
          live.device_losses, live.reconnects);
    }
    if (summary.ate) {
      spdlog::info("ATE against the recording's ground truth: {:.1f} mm RMSE over {} poses",
                   summary.ate->rmse_m * 1e3, summary.ate->pairs);
    }
    const std::size_t removed =
        summary.commits.textures_removed +
        (summary.database.server_link ? summary.database.server_link->removed_at_end : 0);
    spdlog::info(
        "textures: {} patches textured, {} reuse a stored texture, {} new textures in {}{}; "
        "{:.2f} MB before, {:.2f} MB after reuse",
        summary.economy.textured_patches, summary.economy.reuses,
        summary.commits.textures_stored - removed, summary.database.location,
        removed > 0 ? fmt::format(" ({} more removed: older versions of patches)", removed) : "",
        3e-6 * static_cast<double>(summary.economy.pixels_before),
        3e-6 * static_cast<double>(summary.economy.pixels_after));
    // As the method's paper tabulates its runs.
    spdlog::info(
        "summary: {} planes | non-pattern textures {} generated / {} matched | patterns {} "
        "generated / {} matched | texture {:.2f} MB before / {:.2f} MB after{}",
        summary.patches.patches_finalized,
        summary.commits.textures_stored - summary.commits.patterns_stored,
        summary.economy.textures_matched, summary.commits.patterns_stored,
        summary.economy.patterns_matched, 3e-6 * static_cast<double>(summary.economy.pixels_before),
        3e-6 * static_cast<double>(summary.economy.pixels_after),
        summary.economy.pixels_after > 0
            ? fmt::format(" ({:.1f}x)", static_cast<double>(summary.economy.pixels_before) /
                                            static_cast<double>(summary.economy.pixels_after))
            : std::string());
    spdlog::info("TSDF {:.1f} MB, mesh {} vertices, peak RSS {:.0f} MB; wrote {}/",
                 static_cast<double>(summary.integration.tsdf_bytes) / 1e6,
                 summary.exported.mesh_vertices, summary.peak_rss_mb, out_dir);
    return 0;
  } catch (const core::Error& e) {
    spdlog::error("{}", e.what());
    return 1;
  }
}

}  // namespace tessera::cli
