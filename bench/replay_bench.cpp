// Replay throughput: runs `tessera run`'s pipeline over a recording several times and prints
// frames/s for the whole run and per stage (median over the repeats), plus peak memory.
//
//   replay_bench [SOURCE] [--repeat N] [--threads N] [--max-frames N] [--poses track|gt]
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
#include "tessera/core/error.h"
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
  app.add_option("--poses", poses, "track (odometry) or gt (ground-truth poses)")
      ->check(CLI::IsMember({"track", "gt"}));
  app.add_option("SOURCE", source_path, "Dataset folder to replay");
  app.add_option("--repeat", repeat, "Runs to take the median over")->check(CLI::PositiveNumber);
  app.add_option("--threads", threads, "Worker threads (0: all cores)");
  app.add_option("--max-frames", max_frames, "Frames per run (0: all)");
  CLI11_PARSE(app, argc, argv);

  source_path = tessera::bench::resolvedSource(source_path);
  tessera::core::initLogging("warn");
  threads = threads > 0 ? threads : pipeline::defaultThreadCount();
  cv::setNumThreads(threads);

  try {
    std::vector<double> fps;
    std::map<std::string, std::vector<double>> stage_median_ms, stage_alone_fps;
    std::size_t frames = 0, tsdf_bytes = 0;
    for (int run = 0; run < repeat; ++run) {
      const auto source = tessera::bench::openSource(source_path);
      pipeline::RunOptions options;
      options.out_dir = fs::temp_directory_path() / "tessera_replay_bench";
      options.threads = threads;
      options.poses =
          poses == "gt" ? pipeline::PoseSource::kGroundTruth : pipeline::PoseSource::kTrack;
      if (max_frames > 0) options.max_frames = max_frames;
      const auto summary =
          pipeline::runPipeline(*source, pipeline::loadRunConfig(std::nullopt), options);
      fps.push_back(summary.fps);
      frames = summary.frames;
      tsdf_bytes = summary.tsdf_bytes;
      for (const auto& stage : summary.stages) {
        stage_median_ms[stage.name].push_back(stage.median_ms);
        stage_alone_fps[stage.name].push_back(stage.alone_fps);
      }
      fmt::print("run {}: {} frames, {:.2f} s, {:.1f} frames/s\n", run + 1, summary.frames,
                 summary.wall_s, summary.fps);
    }
    fmt::print("\nreplay of {} ({} frames, {} threads, poses: {}, median of {} runs)\n",
               source_path, frames, threads, poses, repeat);
    // The first run pays for fresh memory pages (as a `tessera run` process does); later runs
    // reuse the freed heap. Both are printed.
    fmt::print("  whole pipeline   {:8.1f} frames/s (first run {:.1f})\n", median(fps),
               fps.front());
    for (const auto& [name, values] : stage_median_ms) {
      fmt::print("  stage {:<10} {:8.2f} ms/frame (median)  {:8.1f} frames/s alone\n", name,
                 median(values), median(stage_alone_fps[name]));
    }
    fmt::print("  TSDF             {:8.1f} MB\n", static_cast<double>(tsdf_bytes) / 1e6);
    fmt::print("  peak RSS         {:8.1f} MB\n", pipeline::peakRssMb());
  } catch (const tessera::core::Error& e) {
    fmt::print(stderr, "replay_bench: {}\n", e.what());
    return 1;
  }
  return 0;
}
