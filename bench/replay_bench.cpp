// Replay throughput: runs `tessera run`'s pipeline over a recording several times and prints
// frames/s for the whole run and per stage (median over the repeats), plus peak memory; then
// the plain Open3D loop (legacy RGB-D odometry + ScalableTSDFVolume) over the same frames on
// the same machine, and the ratio of the two. CPU time per frame (every thread) for both: for
// tessera while streaming (report.json's cpu_ms_per_frame), and the end of the stream apart.
//
//   replay_bench [SOURCE] [--repeat N] [--threads N] [--max-frames N] [--poses track|gt]
//                [--intrinsics fx,fy,cx,cy] [--depth-scale UNITS_PER_M] [--skip-open3d]
//
// SOURCE (a dataset folder or an .oni recording) defaults to ../shared/data/rgbd/tum_fr1_rpy_40,
// else the committed recordings/tum_fr1_rpy_20.oni.
#include <algorithm>
#include <filesystem>
#include <map>

#include <fmt/format.h>
#include <CLI/CLI.hpp>
#include <opencv2/core/utility.hpp>

#include "bench_frames.h"
#include "open3d_loop.h"
#include "tessera/core/cpu_time.h"
#include "tessera/core/error.h"
#include "tessera/core/intrinsics.h"
#include "tessera/core/log.h"
#include "tessera/pipeline/flow_graph.h"
#include "tessera/pipeline/run.h"

namespace {

double median(std::vector<double> values) {
  std::sort(values.begin(), values.end());
  return values.empty() ? 0.0 : values[values.size() / 2];
}

}  // namespace

int main(int argc, char** argv) {
  namespace fs = std::filesystem;
  namespace pipeline = tessera::pipeline;
  CLI::App app{"Replay throughput of the tessera pipeline"};
  std::string source_path;
  int repeat = 3;
  int threads = 0;
  std::size_t max_frames = 0;
  std::string poses = "track";
  std::string intrinsics_spec;
  std::optional<double> depth_units_per_m;
  bool skip_open3d = false;
  app.add_option("--poses", poses, "track (odometry) or gt (ground-truth poses)")
      ->check(CLI::IsMember({"track", "gt"}));
  app.add_option("SOURCE", source_path, "Dataset folder to replay");
  app.add_option("--repeat", repeat, "Runs to take the median over")->check(CLI::PositiveNumber);
  app.add_option("--threads", threads, "Worker threads (0: all cores)");
  app.add_option("--max-frames", max_frames, "Frames per run (0: all)");
  app.add_option("--intrinsics", intrinsics_spec, "fx,fy,cx,cy as given to tessera run");
  app.add_option("--depth-scale", depth_units_per_m, "Raw depth units per metre");
  app.add_flag("--skip-open3d", skip_open3d, "Leave out the plain Open3D loop (it is slow)");
  CLI11_PARSE(app, argc, argv);

  source_path = tessera::bench::resolvedSource(source_path);
  tessera::core::initLogging("warn");
  threads = threads > 0 ? threads : pipeline::defaultThreadCount();
  cv::setNumThreads(threads);

  try {
    std::optional<tessera::core::Intrinsics> intrinsics;
    if (!intrinsics_spec.empty()) intrinsics = tessera::core::parseIntrinsicsSpec(intrinsics_spec);
    std::vector<double> fps, cpu_ms_per_frame, cpu_s_after;
    std::map<std::string, std::vector<double>> stage_median_ms, stage_alone_fps;
    std::map<std::string, std::size_t> stage_calls;  // in the last run
    std::size_t frames = 0, tsdf_bytes = 0;
    for (int run = 0; run < repeat; ++run) {
      const auto source = tessera::bench::openSource(source_path, intrinsics, depth_units_per_m);
      pipeline::RunOptions options;
      options.out_dir = fs::temp_directory_path() / "tessera_replay_bench";
      options.threads = threads;
      options.poses =
          poses == "gt" ? pipeline::PoseSource::kGroundTruth : pipeline::PoseSource::kTrack;
      if (max_frames > 0) options.max_frames = max_frames;
      const auto summary =
          pipeline::runPipeline(*source, pipeline::loadRunConfig(std::nullopt), options);
      fps.push_back(summary.fps);
      const std::size_t streamed = std::max<std::size_t>(summary.stream.frames, 1);
      cpu_ms_per_frame.push_back(1e3 * summary.cpu.stream_s / static_cast<double>(streamed));
      cpu_s_after.push_back(summary.cpu.end_of_stream_s + summary.cpu.finish_s);
      frames = summary.stream.frames;
      tsdf_bytes = summary.integration.tsdf_bytes;
      for (const auto& stage : summary.stages) {
        stage_median_ms[stage.name].push_back(stage.median_ms);
        stage_alone_fps[stage.name].push_back(stage.alone_fps);
        stage_calls[stage.name] = stage.calls;
      }
      fmt::print("run {}: {} frames, {:.2f} s, {:.1f} frames/s\n", run + 1, summary.stream.frames,
                 summary.wall_s, summary.fps);
    }
    fmt::print("\nreplay of {} ({} frames, {} threads, poses: {}, median of {} runs)\n",
               source_path, frames, threads, poses, repeat);
    // The first run pays for fresh memory pages (as a `tessera run` process does); later runs
    // reuse the freed heap. Both are printed.
    fmt::print("  whole pipeline   {:8.1f} frames/s (first run {:.1f})\n", median(fps),
               fps.front());
    fmt::print("  CPU              {:8.1f} ms a frame while streaming, every thread; then {:.1f} s "
               "to end the stream and finish\n",
               median(cpu_ms_per_frame), median(cpu_s_after));
    // A call is a frame for the frame stages and a patch for the texture stages (match,
    // textures, commit), so their rates are calls, not frames.
    for (const auto& [name, values] : stage_median_ms) {
      fmt::print("  stage {:<10} {:8.2f} ms a call (median, {} calls)  {:8.1f} calls/s alone\n",
                 name, median(values), stage_calls[name], median(stage_alone_fps[name]));
    }
    fmt::print("  TSDF             {:8.1f} MB\n", static_cast<double>(tsdf_bytes) / 1e6);
    fmt::print("  peak RSS         {:8.1f} MB\n", pipeline::peakRssMb());
    if (!skip_open3d) {
      // The same frames, held in memory so that the loop's time has no decoding in it (which
      // favours the loop: tessera's figures above include reading the recording).
      const auto loaded = tessera::bench::loadFrames(source_path, max_frames, /*need_truth=*/false,
                                                     intrinsics, depth_units_per_m);
      const double cpu_before_s = tessera::core::processCpuSeconds();
      const auto loop = tessera::bench::plainOpen3dLoop(loaded, tessera::fusion::TsdfConfig{});
      const double loop_cpu_ms = 1e3 * (tessera::core::processCpuSeconds() - cpu_before_s) /
                                 static_cast<double>(std::max<std::size_t>(loaded.size(), 1));
      const double loop_fps = 1000.0 / loop.ms_per_frame;
      fmt::print("  plain Open3D loop {:7.1f} frames/s ({} frames in memory{}{})\n", loop_fps,
                 loaded.size(),
                 loop.ate_mm ? fmt::format(", ATE {:.1f} mm", *loop.ate_mm) : std::string(),
                 loop.odometry_failures > 0
                     ? fmt::format(", {} odometry failures", loop.odometry_failures)
                     : std::string());
      fmt::print("  plain Open3D CPU {:8.1f} ms a frame, every thread (odometry and integration)\n",
                 loop_cpu_ms);
      fmt::print("  tessera / Open3D {:8.1f}x\n", median(fps) / loop_fps);
    }
  } catch (const tessera::core::Error& e) {
    fmt::print(stderr, "replay_bench: {}\n", e.what());
    return 1;
  }
  return 0;
}
