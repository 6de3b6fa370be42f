// Loop closure on a recording: tracks every frame, hands the tracker's keyframes to the loop
// graph in the same thread, and prints what it found, where its time went and the ATE of the
// tracked and of the corrected trajectory.
//
//   loop_bench [SOURCE] [--max-frames N] [--config FILE] [--intrinsics ...] [--depth-scale U]
#include <chrono>

#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <opencv2/core/utility.hpp>

#include "bench_frames.h"
#include "tessera/core/error.h"
#include "tessera/core/log.h"
#include "tessera/core/registration.h"
#include "tessera/core/trajectory.h"
#include "tessera/fusion/tracker.h"
#include "tessera/loop/loop_graph.h"
#include "tessera/pipeline/run_config.h"

int main(int argc, char** argv) {
  namespace bench = tessera::bench;
  namespace fusion = tessera::fusion;
  CLI::App app{"Loop closure: loops found, time per stage, ATE before and after"};
  std::string source_path, intrinsics_spec, config_path;
  std::size_t max_frames = 0;
  std::optional<double> depth_units_per_m;
  app.add_option("SOURCE", source_path, "Dataset folder or .oni recording with ground truth");
  app.add_option("--max-frames", max_frames, "Frames to read (0: all)");
  app.add_option("--config", config_path, "tessera run configuration (tracker, loop_closure)");
  app.add_option("--intrinsics", intrinsics_spec, "fx,fy,cx,cy as given to tessera run");
  app.add_option("--depth-scale", depth_units_per_m, "Raw depth units per metre");
  CLI11_PARSE(app, argc, argv);
  tessera::core::initLogging("warn");
  cv::setNumThreads(1);

  try {
    const auto config = tessera::pipeline::loadRunConfig(
        config_path.empty() ? std::nullopt : std::optional<std::filesystem::path>(config_path));
    std::optional<tessera::core::Intrinsics> intrinsics;
    if (!intrinsics_spec.empty()) intrinsics = tessera::core::parseIntrinsicsSpec(intrinsics_spec);
    source_path = bench::resolvedSource(source_path);
    auto source = bench::openSource(source_path, intrinsics, depth_units_per_m);
    fusion::Tracker tracker(config.tracker);
    tessera::loop::LoopGraph graph(config.loop_closure);
    tessera::core::Trajectory estimate, truth;
    std::optional<tessera::core::Isometry> first_truth;
    double tracking_ms = 0.0;
    std::size_t frames = 0;
    for (;;) {
      if (max_frames > 0 && frames >= max_frames) break;
      tessera::core::ReadResult read = source->read();
      if (read.status == tessera::core::ReadStatus::kEndOfData) break;
      if (read.status != tessera::core::ReadStatus::kFrame) continue;
      tessera::core::Frame frame = tessera::core::withRegisteredColour(std::move(read.frame));
      ++frames;
      if (frame.T_W_C_gt) {
        truth[frame.timestamp_ns] = *frame.T_W_C_gt;
        if (!first_truth) first_truth = frame.T_W_C_gt;
      }
      const auto start = std::chrono::steady_clock::now();
      const auto result =
          tracker.track(frame, first_truth.value_or(tessera::core::Isometry::Identity()));
      tracking_ms +=
          std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
      if (result.status == fusion::TrackingStatus::kLost) continue;
      estimate[frame.timestamp_ns] = result.T_W_C;
      for (const auto& keyframe : result.new_keyframes) graph.add(*keyframe);
    }
    graph.finish();
    const auto& s = graph.stats();
    fmt::print("{}: {} frames, {} keyframes; tracking {:.1f} ms/frame\n", source_path, frames,
               s.keyframes, tracking_ms / static_cast<double>(std::max<std::size_t>(1, frames)));
    fmt::print(
        "loop closure: {:.1f} ms/keyframe ({:.1f} ms/frame): information {:.1f}, place lookup "
        "{:.1f}, place index {:.1f}, checks {:.1f} ms/keyframe; pose graph {} runs, {:.0f} ms in "
        "all\n",
        s.keyframe_ms / static_cast<double>(std::max<std::size_t>(1, s.keyframes)),
        s.keyframe_ms / static_cast<double>(std::max<std::size_t>(1, frames)),
        s.information_ms / static_cast<double>(std::max<std::size_t>(1, s.keyframes)),
        s.place_lookup_ms / static_cast<double>(std::max<std::size_t>(1, s.keyframes)),
        s.place_index_ms / static_cast<double>(std::max<std::size_t>(1, s.keyframes)),
        s.verification_ms / static_cast<double>(std::max<std::size_t>(1, s.keyframes)), s.optimisations,
        s.pose_graph_ms);
    fmt::print(
        "candidates {}, verified {}, rejected: {} as drift, {} unconfirmed, {} by the graph; "
        "loops closed {}\n",
        s.candidates_checked, s.revisits_verified, s.rejected_as_drift, s.rejected_unconfirmed,
        s.rejected_by_graph, s.loop_closures);
    for (const auto& loop : graph.loops()) {
      fmt::print("  loop: keyframe {} -> {} (fitness {:.2f}, rms {:.1f} mm, {} inliers)\n",
                 loop.query, loop.match, loop.revisit.fitness, loop.revisit.rmse_m * 1e3,
                 loop.revisit.feature_inliers);
    }
    const auto before = tessera::core::absoluteTrajectoryError(estimate, truth);
    const auto after = tessera::core::absoluteTrajectoryError(graph.correct(estimate), truth);
    if (before && after) {
      fmt::print("ATE tracked {:.1f} mm RMSE ({:.1f} max); after closure {:.1f} mm ({:.1f} max)\n",
                 before->rmse_m * 1e3, before->max_m * 1e3, after->rmse_m * 1e3,
                 after->max_m * 1e3);
    }
  } catch (const std::exception& e) {
    fmt::print(stderr, "loop_bench: {}\n", e.what());
    return 1;
  }
  return 0;
}
