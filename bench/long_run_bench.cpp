// Hours on a robot, compressed: replays a recording lap after lap as one stream, with its time
// stamps carried on, so that a loop scene is walked round again and every place revisited, and
// runs `tessera run`'s pipeline over it. From the run's own stats.jsonl it prints what a robot
// team needs to know about a long run:
//   - resident memory: its growth per 1,000 frames over the second half, and its peak;
//   - frames/s and CPU time per frame (every thread);
//   - commit latency (finalization to commit) p50 and p95 in each quarter of the run.
//
//   long_run_bench SOURCE [--laps N] [--threads N] [--config FILE] [--out DIR] [--poses track|gt]
//
// SOURCE is an .oni recording or a dataset folder, e.g. the loop scene rendered outside git:
//   tessera synth config/scenes/loop.yaml /tmp/loop.oni   (1,500 frames; 7 laps: 10,500)
#include <algorithm>
#include <filesystem>
#include <fstream>
#include <vector>

#include <fmt/format.h>
#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "bench_frames.h"
#include "tessera/core/error.h"
#include "tessera/core/log.h"
#include "tessera/core/quantiles.h"
#include "tessera/pipeline/flow_graph.h"
#include "tessera/pipeline/run.h"

namespace {

namespace core = tessera::core;

// The recording `laps` times over as one stream: frames renumbered, and each lap's time stamps
// shifted to follow the lap before by one frame period.
class LapSource : public core::FrameSource {
 public:
  LapSource(std::string path, int laps) : path_(std::move(path)), laps_(laps) { openLap(); }

  core::ReadResult read() override {
    for (;;) {
      core::ReadResult result = lap_->read();
      if (result.status == core::ReadStatus::kEndOfData && result.problem.empty() &&
          lap_number_ + 1 < laps_) {
        shift_ns_ = last_ns_ + period_ns_;
        first_of_lap_ = true;
        ++lap_number_;
        openLap();
        continue;
      }
      if (result.status != core::ReadStatus::kFrame) return result;
      core::Frame& frame = result.frame;
      if (first_of_lap_) {
        shift_ns_ -= frame.timestamp_ns;
        first_of_lap_ = false;
      } else if (lap_number_ == 0 && next_index_ > 0) {
        period_ns_ = frame.timestamp_ns - last_raw_ns_;
      }
      last_raw_ns_ = frame.timestamp_ns;
      frame.index = next_index_++;
      frame.timestamp_ns += shift_ns_;
      if (frame.colour_timestamp_ns) *frame.colour_timestamp_ns += shift_ns_;
      last_ns_ = frame.timestamp_ns;
      return result;
    }
  }
  std::string name() const override { return fmt::format("{} x{}", path_, laps_); }
  std::optional<std::size_t> frameCount() const override {
    const auto lap = lap_->frameCount();
    return lap ? std::optional<std::size_t>(*lap * static_cast<std::size_t>(laps_)) : std::nullopt;
  }

 private:
  void openLap() { lap_ = tessera::bench::openSource(path_); }

  std::string path_;
  int laps_;
  int lap_number_ = 0;
  std::unique_ptr<core::FrameSource> lap_;
  std::uint64_t next_index_ = 0;
  std::int64_t shift_ns_ = 0, last_ns_ = 0, last_raw_ns_ = 0;
  std::int64_t period_ns_ = 33'333'333;
  bool first_of_lap_ = false;
};

struct FrameLine {
  double elapsed_s = 0.0, rss_mb = 0.0, cpu_ms = 0.0;
};

}  // namespace

int main(int argc, char** argv) {
  namespace fs = std::filesystem;
  namespace pipeline = tessera::pipeline;
  CLI::App app{
      "Memory, CPU and commit latency over a long run (a recording replayed lap after lap)"};
  std::string source_path;
  int laps = 7;
  int threads = 0;
  std::optional<fs::path> config_path;
  fs::path out_dir = fs::temp_directory_path() / "tessera_long_run_bench";
  std::string poses = "track";
  app.add_option("SOURCE", source_path, "Recording (.oni) or dataset folder")->required();
  app.add_option("--laps", laps, "Times the recording is played, as one stream")
      ->check(CLI::PositiveNumber);
  app.add_option("--threads", threads, "Worker threads (0: all cores)");
  app.add_option("--config", config_path, "YAML config, as tessera run --config");
  app.add_option("--out", out_dir, "Output folder of the run");
  app.add_option("--poses", poses, "track (odometry) or gt (ground-truth poses)")
      ->check(CLI::IsMember({"track", "gt"}));
  std::string log_level = "warn";
  app.add_option("--log-level", log_level, "The run's log on stderr, as tessera --log-level")
      ->check(CLI::IsMember({"trace", "debug", "info", "warn", "error", "off"}));
  CLI11_PARSE(app, argc, argv);
  tessera::core::initLogging(log_level);

  try {
    LapSource source(source_path, laps);
    pipeline::RunOptions options;
    options.out_dir = out_dir;
    options.threads = threads;
    options.poses =
        poses == "gt" ? pipeline::PoseSource::kGroundTruth : pipeline::PoseSource::kTrack;
    const std::size_t expected = source.frameCount().value_or(0);
    options.on_progress = [expected](const pipeline::Progress& progress) {
      if (progress.frames_done % 1000 == 0) {
        fmt::print(stderr, "  {} / {} frames, {:.0f} s\n", progress.frames_done, expected,
                   progress.elapsed_s);
      }
    };
    const pipeline::RunSummary summary =
        pipeline::runPipeline(source, pipeline::loadRunConfig(config_path), options);

    // Frames and commits as the run logged them.
    std::vector<FrameLine> frames;
    std::vector<std::pair<std::size_t, double>> commits;  // frames done, latency
    std::ifstream stats(out_dir / "stats.jsonl");
    for (std::string text; std::getline(stats, text);) {
      const auto line = nlohmann::json::parse(text);
      if (line["type"] == "frame") {
        frames.push_back({line["elapsed_s"], line["rss_mb"], line.value("cpu_ms", 0.0)});
      } else if (line["type"] == "patch" && line["event"] == "committed" &&
                 line["committed"] == true) {
        commits.emplace_back(frames.size(), line["commit_latency_ms"]);
      }
    }
    if (frames.empty()) throw core::Error(fmt::format("{}: no frames ran", source_path));

    double peak_rss = 0.0;
    for (const FrameLine& frame : frames) peak_rss = std::max(peak_rss, frame.rss_mb);
    fmt::print("\nlong run: {} ({} frames, {} threads)\n", source.name(), frames.size(),
               threads > 0 ? threads : pipeline::defaultThreadCount());
    fmt::print("  RSS growth, second half  {:8.1f} MB per 1,000 frames\n",
               summary.stream.rss_growth_mb_per_1000_frames.value_or(0.0));
    fmt::print("  peak RSS (frames)        {:8.1f} MB (process peak {:.1f} MB)\n", peak_rss,
               summary.peak_rss_mb);
    fmt::print("  frames/s                 {:8.1f}\n", summary.fps);
    fmt::print("  CPU per frame (stream)   {:8.1f} ms, {:.2f} cores\n",
               1e3 * summary.cpu.stream_s / static_cast<double>(frames.size()),
               summary.cpu.stream_s / std::max(1e-9, summary.cpu.elapsed_stream_s));
    fmt::print("  CPU after the stream     {:8.1f} s end of stream, {:.1f} s finish\n",
               summary.cpu.end_of_stream_s, summary.cpu.finish_s);
    const std::size_t quarter = (frames.size() + 3) / 4;
    for (std::size_t q = 0; q < 4; ++q) {
      core::Quantiles latency;
      double rss_end = 0.0;
      for (const auto& [done, ms] : commits) {
        if (done > q * quarter && done <= (q + 1) * quarter) latency.add(ms);
      }
      rss_end = frames[std::min(frames.size(), (q + 1) * quarter) - 1].rss_mb;
      fmt::print(
          "  quarter {}: {:4} commits, latency p50 {:7.0f} ms, p95 {:7.0f} ms; RSS {:6.0f} MB at "
          "its end\n",
          q + 1, latency.count(), latency.quantile(0.5).value_or(0.0),
          latency.quantile(0.95).value_or(0.0), rss_end);
    }
  } catch (const std::exception& e) {
    fmt::print(stderr, "long_run_bench: {}\n", e.what());
    return 1;
  }
  return 0;
}
