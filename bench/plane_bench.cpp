// Per-frame plane detection time: PlaneDetector over a recording's frames at full and half
// working resolution, median ms per frame and planes found per frame.
//
//   plane_bench [SOURCE] [--max-frames N] [--threads N]
#include <algorithm>

#include <fmt/format.h>
#include <CLI/CLI.hpp>
#include <opencv2/core/utility.hpp>

#include "bench_frames.h"
#include "tessera/core/error.h"
#include "tessera/core/log.h"
#include "tessera/planes/plane_detector.h"

int main(int argc, char** argv) {
  CLI::App app{"Plane detection time per frame"};
  std::string source_path;
  std::size_t max_frames = 100;
  int threads = 1;
  app.add_option("SOURCE", source_path, "Dataset folder or .oni recording");
  app.add_option("--max-frames", max_frames, "Frames to use (0: all)");
  app.add_option("--threads", threads, "OpenCV threads")->check(CLI::PositiveNumber);
  CLI11_PARSE(app, argc, argv);
  tessera::core::initLogging("warn");
  cv::setNumThreads(threads);
  try {
    const auto frames = tessera::bench::loadFrames(source_path, max_frames, false);
    fmt::print("{} frames from {}, {} thread(s)\n", frames.size(),
               tessera::bench::resolvedSource(source_path), threads);
    for (const int scale : {1, 2}) {
      tessera::planes::PlaneDetectorConfig config;
      config.working_scale = scale;
      config.block_size = 40 / scale;
      config.min_pixels = 4800 / (scale * scale);
      const tessera::planes::PlaneDetector detector(config);
      std::vector<double> ms;
      std::size_t planes = 0;
      for (const auto& frame : frames) {
        const auto start = std::chrono::steady_clock::now();
        planes += detector.detect(frame).planes.size();
        ms.push_back(
            std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
                .count());
      }
      std::sort(ms.begin(), ms.end());
      fmt::print(
          "  working resolution 1/{}: {:6.2f} ms/frame median, {:6.2f} p95, {:.1f} planes/frame\n",
          scale, ms[ms.size() / 2], ms[ms.size() * 95 / 100],
          static_cast<double>(planes) / static_cast<double>(frames.size()));
    }
  } catch (const tessera::core::Error& e) {
    fmt::print(stderr, "plane_bench: {}\n", e.what());
    return 1;
  }
  return 0;
}
