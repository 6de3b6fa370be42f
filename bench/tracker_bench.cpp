// The camera tracker alone, over frames held in memory: ms per frame, frames lost and
// restarted, and the ATE against the recording's ground truth. Tracker options are given on
// the command line, so that choices (resolution, iterations, motion guess) are compared on
// the same frames. --every N keeps every N-th frame only, as when a live source drops frames.
//
//   tracker_bench [SOURCE] [--every N] [--max-frames N] [--scale 1|2|4]
//                 [--iterations 3,3,4,6] [--no-velocity] [--intrinsics ...] [--depth-scale U]
#include <algorithm>
#include <chrono>

#include <fmt/format.h>
#include <CLI/CLI.hpp>
#include <opencv2/core/utility.hpp>

#include "bench_frames.h"
#include "tessera/core/error.h"
#include "tessera/core/log.h"
#include "tessera/core/pose.h"
#include "tessera/core/trajectory.h"
#include "tessera/fusion/tracker.h"

namespace {

std::vector<int> parseIterations(const std::string& text) {
  std::vector<int> levels;
  std::size_t start = 0;
  while (start <= text.size()) {
    const std::size_t comma = std::min(text.find(',', start), text.size());
    levels.push_back(std::stoi(text.substr(start, comma - start)));
    start = comma + 1;
  }
  return levels;
}

}  // namespace

int main(int argc, char** argv) {
  namespace bench = tessera::bench;
  namespace fusion = tessera::fusion;
  CLI::App app{"Camera tracker speed and accuracy"};
  std::string source_path, iterations, intrinsics_spec;
  std::size_t every = 1, max_frames = 0;
  std::optional<double> depth_units_per_m;
  fusion::TrackerConfig config;
  bool no_velocity = false, verbose = false;
  app.add_option("SOURCE", source_path, "Dataset folder or .oni recording with ground truth");
  app.add_option("--every", every, "Keep every N-th frame only")->check(CLI::PositiveNumber);
  app.add_option("--max-frames", max_frames, "Frames to load before --every (0: all)");
  app.add_option("--scale", config.tracking_scale, "Track on every N-th pixel (1, 2 or 4)")
      ->check(CLI::IsMember({1, 2, 4}));
  app.add_option("--keyframe-m", config.keyframe_translation_m, "Keyframe after this motion");
  app.add_option("--keyframe-deg", config.keyframe_rotation_deg, "Keyframe after this turn");
  app.add_option("--feature-gap", config.feature_gap_s,
                 "Pose from features first after this gap, s");
  app.add_option("--iterations", iterations, "Iterations per pyramid level, finest first");
  app.add_flag("--no-velocity", no_velocity, "Start each solve from no motion");
  app.add_option("--lost-frames", config.lost_frames_before_restart,
                 "Lost frames in a row before tracking restarts")
      ->check(CLI::PositiveNumber);
  app.add_flag("--verbose", verbose, "Print each frame whose step is off by more than 5 mm");
  app.add_option("--intrinsics", intrinsics_spec, "fx,fy,cx,cy as given to tessera run");
  app.add_option("--depth-scale", depth_units_per_m, "Raw depth units per metre");
  CLI11_PARSE(app, argc, argv);
  if (!iterations.empty()) config.iterations_per_level = parseIterations(iterations);
  config.constant_velocity = !no_velocity;
  tessera::core::initLogging("warn");
  cv::setNumThreads(1);  // one core, as the tracking stage gets in the pipeline

  try {
    std::optional<tessera::core::Intrinsics> intrinsics;
    if (!intrinsics_spec.empty()) intrinsics = tessera::core::parseIntrinsicsSpec(intrinsics_spec);
    source_path = bench::resolvedSource(source_path);
    const auto all =
        bench::loadFrames(source_path, max_frames, true, intrinsics, depth_units_per_m);
    fusion::Tracker tracker(config);
    tessera::core::Trajectory estimate, truth;
    std::vector<double> ms;
    int lost = 0, restarts = 0, relocalised = 0;
    std::pair<double, std::uint64_t> worst_step{0.0, 0};
    for (std::size_t i = 0; i < all.size(); i += every) {
      const auto& frame = all[i];
      truth[frame.timestamp_ns] = *frame.T_W_C_gt;
      const auto start = std::chrono::steady_clock::now();
      const fusion::TrackingResult result = tracker.track(frame, *all.front().T_W_C_gt);
      ms.push_back(
          std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
              .count());
      if (result.status == fusion::TrackingStatus::kLost) {
        if (verbose) fmt::print("frame {}: lost: {}\n", frame.index, result.problem);
        ++lost;
        continue;
      }
      if (result.status == fusion::TrackingStatus::kRestarted) ++restarts;
      if (result.status == fusion::TrackingStatus::kRelocalised) {
        ++relocalised;
        if (verbose) fmt::print("frame {}: relocalised\n", frame.index);
      }
      // The step's error: this frame's pose relative to the last tracked one, against the truth.
      if (!estimate.empty() && result.status == fusion::TrackingStatus::kTracked) {
        const auto& [last_ns, last_T] = *estimate.rbegin();
        const auto step = last_T.inverse() * result.T_W_C;
        const auto true_step = truth.at(last_ns).inverse() * *frame.T_W_C_gt;
        const double error_mm = (step.translation() - true_step.translation()).norm() * 1e3;
        worst_step = std::max(worst_step, {error_mm, frame.index});
        const double turn_error_deg = tessera::core::rotationAngleDeg(true_step.inverse() * step);
        if (verbose && (error_mm > 5.0 || turn_error_deg > 0.2)) {
          fmt::print("frame {}: step off by {:.1f} mm, {:.2f} deg\n", frame.index, error_mm,
                     turn_error_deg);
        }
      }
      estimate[frame.timestamp_ns] = result.T_W_C;
    }
    std::vector<double> sorted = ms;
    std::sort(sorted.begin(), sorted.end());
    double mean = 0.0;
    for (double v : ms) mean += v / static_cast<double>(ms.size());
    const auto ate = tessera::core::absoluteTrajectoryError(estimate, truth);
    fmt::print(
        "{}: {} frames (every {}), scale {}, iterations [{}], velocity {}: {:.1f} ms/frame mean, "
        "{:.1f} median; lost {}, relocalised {}, restarts {}; worst step {:.1f} mm (frame {}); "
        "ATE {}\n",
        source_path, ms.size(), every, config.tracking_scale,
        fmt::join(config.iterations_per_level, ","), config.constant_velocity ? "on" : "off", mean,
        sorted[sorted.size() / 2], lost, relocalised, restarts, worst_step.first, worst_step.second,
        ate ? fmt::format("{:.1f} mm RMSE, {:.1f} mm max", ate->rmse_m * 1e3, ate->max_m * 1e3)
            : std::string("n/a"));
  } catch (const tessera::core::Error& e) {
    fmt::print(stderr, "tracker_bench: {}\n", e.what());
    return 1;
  } catch (const std::exception& e) {
    fmt::print(stderr, "tracker_bench: {}\n", e.what());
    return 1;
  }
  return 0;
}
