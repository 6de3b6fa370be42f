// The measurements behind the tracking and TSDF choices in docs/MEASUREMENTS.md. Every option
// runs over the same frames, held in memory so decoding is not timed:
//   - TSDF integration at ground-truth poses: Open3D's ScalableTSDFVolume (legacy) and
//     VoxelBlockGrid (tensor, CPU), at full and half depth resolution, plus VoxelBlockGrid's
//     raycast (what frame-to-model tracking needs);
//   - tracking: OpenCV's RgbdICPOdometry frame to frame, and frame-to-model (VoxelBlockGrid
//     raycast, then the same odometry against the model view), at full and half resolution,
//     with the ATE of each trajectory;
//   - tessera's whole pipeline (tracking + fusion) against a plain Open3D loop on the same
//     frames: Open3D's legacy RGB-D odometry + ScalableTSDFVolume, printed as a ratio.
//
//   fusion_options_bench [SOURCE] [--max-frames N] [--threads N] [--skip-options]
//                        [--intrinsics fx,fy,cx,cy] [--depth-scale UNITS_PER_M]
#include <chrono>
#include <filesystem>
#include <functional>
#include <optional>

#include <fmt/format.h>
#include <omp.h>
#include <open3d/core/EigenConverter.h>
#include <open3d/geometry/Image.h>
#include <open3d/geometry/RGBDImage.h>
#include <open3d/pipelines/integration/ScalableTSDFVolume.h>
#include <open3d/t/geometry/Image.h>
#include <open3d/t/geometry/Utility.h>
#include <open3d/t/geometry/VoxelBlockGrid.h>
#include <open3d/utility/Logging.h>
#include <CLI/CLI.hpp>
#include <opencv2/core/eigen.hpp>
#include <opencv2/core/utility.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/rgbd.hpp>

#include "bench_frames.h"
#include "open3d_loop.h"
#include "tessera/core/intrinsics.h"
#include "tessera/core/log.h"
#include "tessera/core/trajectory.h"
#include "tessera/fusion/tsdf_map.h"
#include "tessera/pipeline/run.h"

namespace {

namespace o3d = open3d;
using tessera::core::Frame;
using tessera::core::Isometry;
using Clock = std::chrono::steady_clock;

double msSince(Clock::time_point start) {
  return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

// A frame at `scale` of its resolution: depth by nearest neighbour (no mixing across edges),
// colour by area averaging. Pixel u of the result is pixel factor*u of the frame, as in
// tessera's own integration, so f and c scale by 1/factor.
struct ScaledFrame {
  cv::Mat depth_mm, rgb;
  double fx, fy, cx, cy;
  int width, height;
};

ScaledFrame scaled(const Frame& frame, int factor) {
  ScaledFrame out;
  const auto& k = frame.intrinsics;
  out.width = k.width / factor;
  out.height = k.height / factor;
  out.fx = k.fx / factor;
  out.fy = k.fy / factor;
  out.cx = k.cx / factor;
  out.cy = k.cy / factor;
  if (factor == 1) {
    out.depth_mm = frame.depth_mm;
    out.rgb = frame.rgb;
  } else {
    cv::resize(frame.depth_mm, out.depth_mm, {out.width, out.height}, 0, 0, cv::INTER_NEAREST);
    cv::resize(frame.rgb, out.rgb, {out.width, out.height}, 0, 0, cv::INTER_AREA);
  }
  return out;
}

o3d::t::geometry::Image tensorImage(const cv::Mat& mat) {
  const o3d::core::Dtype dtype = mat.depth() == CV_16U ? o3d::core::UInt16 : o3d::core::UInt8;
  o3d::core::Tensor tensor({mat.rows, mat.cols, mat.channels()}, dtype);
  const cv::Mat contiguous = mat.isContinuous() ? mat : mat.clone();
  std::memcpy(tensor.GetDataPtr(), contiguous.data, contiguous.total() * contiguous.elemSize());
  return o3d::t::geometry::Image(tensor);
}

o3d::core::Tensor tensorIntrinsics(const ScaledFrame& f) {
  return o3d::core::Tensor::Init<double>({{f.fx, 0, f.cx}, {0, f.fy, f.cy}, {0, 0, 1}});
}

o3d::core::Tensor tensorPose(const Isometry& T) {
  return o3d::core::eigen_converter::EigenMatrixToTensor(Eigen::Matrix4d(T.matrix()));
}

struct Timing {
  double ms_per_frame = 0.0;
  std::string note;
};

void printRow(const std::string& name, const Timing& t) {
  fmt::print("  {:<58} {:8.2f} ms/frame {:7.1f} frames/s  {}\n", name, t.ms_per_frame,
             1000.0 / t.ms_per_frame, t.note);
}

constexpr float kTruncVoxels = 3.0f;  // truncation in voxels, as tessera's default (6 cm / 2 cm)

// ATE of a tracked trajectory, and how many frames kept the previous pose because the
// odometry failed.
std::string ateNote(const tessera::core::Trajectory& estimate,
                    const tessera::core::Trajectory& truth, int odometry_failures = 0) {
  const auto ate = tessera::core::absoluteTrajectoryError(estimate, truth);
  std::string note = ate ? fmt::format("ATE {:.1f} mm over {} poses", ate->rmse_m * 1e3, ate->pairs)
                         : std::string("ATE: too few poses");
  if (odometry_failures > 0) note += fmt::format("; {} odometry failures", odometry_failures);
  return note;
}

Timing scalableIntegration(const std::vector<Frame>& frames, int factor, double voxel) {
  o3d::pipelines::integration::ScalableTSDFVolume volume(
      voxel, voxel * kTruncVoxels, o3d::pipelines::integration::TSDFVolumeColorType::RGB8, 16);
  double total = 0.0;
  for (const Frame& frame : frames) {
    const ScaledFrame f = scaled(frame, factor);
    const auto start = Clock::now();
    o3d::geometry::Image depth, colour;
    depth.Prepare(f.width, f.height, 1, 4);
    colour.Prepare(f.width, f.height, 3, 1);
    for (int v = 0; v < f.height; ++v) {
      for (int u = 0; u < f.width; ++u) {
        const auto z = f.depth_mm.at<std::uint16_t>(v, u) * 1e-3f;
        *depth.PointerAt<float>(u, v) = (z >= 0.3f && z <= 4.0f) ? z : 0.0f;
      }
      std::memcpy(colour.PointerAt<std::uint8_t>(0, v, 0), f.rgb.ptr(v),
                  static_cast<std::size_t>(f.width) * 3);
    }
    o3d::geometry::RGBDImage rgbd(colour, depth);
    volume.Integrate(rgbd, {f.width, f.height, f.fx, f.fy, f.cx, f.cy},
                     frame.T_W_C_gt->inverse().matrix());
    total += msSince(start);
  }
  return {total / static_cast<double>(frames.size()),
          fmt::format("{} blocks", volume.volume_units_.size())};
}

o3d::t::geometry::VoxelBlockGrid makeBlockGrid(double voxel) {
  return o3d::t::geometry::VoxelBlockGrid(
      {"tsdf", "weight", "color"}, {o3d::core::Float32, o3d::core::UInt16, o3d::core::UInt16},
      {{1}, {1}, {3}}, static_cast<float>(voxel), 16, 20000);
}

// Integrates `frame` at pose T_W_C; returns the blocks it touched (the raycast's frustum).
o3d::core::Tensor integrateBlockGrid(o3d::t::geometry::VoxelBlockGrid& grid, const ScaledFrame& f,
                                     const Isometry& T_W_C) {
  const auto depth = tensorImage(f.depth_mm);
  const auto colour = tensorImage(f.rgb);
  const auto K = tensorIntrinsics(f);
  const auto T_C_W = tensorPose(T_W_C.inverse());
  const auto blocks = grid.GetUniqueBlockCoordinates(depth, K, T_C_W, 1000.0f, 4.0f, kTruncVoxels);
  grid.Integrate(blocks, depth, colour, K, T_C_W, 1000.0f, 4.0f, kTruncVoxels);
  return blocks;
}

std::pair<Timing, Timing> blockGridIntegration(const std::vector<Frame>& frames, int factor,
                                               double voxel) {
  auto grid = makeBlockGrid(voxel);
  double integrate_ms = 0.0, raycast_ms = 0.0;
  for (const Frame& frame : frames) {
    const ScaledFrame f = scaled(frame, factor);
    auto start = Clock::now();
    const auto blocks = integrateBlockGrid(grid, f, *frame.T_W_C_gt);
    integrate_ms += msSince(start);
    start = Clock::now();
    grid.RayCast(blocks, tensorIntrinsics(f), tensorPose(frame.T_W_C_gt->inverse()), f.width,
                 f.height, {"depth", "normal"}, 1000.0f, 0.3f, 4.0f, 1.0f, kTruncVoxels);
    raycast_ms += msSince(start);
  }
  const double n = static_cast<double>(frames.size());
  return {{integrate_ms / n, fmt::format("{} blocks", grid.GetHashMap().Size())},
          {raycast_ms / n, "depth + normals"}};
}

// OpenCV odometry input: grey image and depth in metres with NaN where invalid.
struct OdometryImages {
  cv::Mat grey, depth;
};

OdometryImages odometryImages(const ScaledFrame& f) {
  OdometryImages out;
  cv::cvtColor(f.rgb, out.grey, cv::COLOR_RGB2GRAY);
  f.depth_mm.convertTo(out.depth, CV_32F, 1e-3);
  out.depth.setTo(std::numeric_limits<float>::quiet_NaN(), f.depth_mm == 0);
  return out;
}

cv::Ptr<cv::rgbd::RgbdICPOdometry> makeOdometry(const ScaledFrame& f) {
  const cv::Mat K = (cv::Mat_<double>(3, 3) << f.fx, 0, f.cx, 0, f.fy, f.cy, 0, 0, 1);
  return cv::rgbd::RgbdICPOdometry::create(K, 0.3f, 4.0f, 0.07f);
}

// The pose of `current` from the odometry that maps `reference` points (seen from
// T_W_reference) into `current`; nothing when the odometry fails.
std::optional<Isometry> odometryStep(cv::rgbd::RgbdICPOdometry& odometry,
                                     const OdometryImages& reference, const OdometryImages& current,
                                     const Isometry& T_W_reference) {
  cv::Mat Rt;
  if (!odometry.compute(reference.grey, reference.depth, cv::Mat(), current.grey, current.depth,
                        cv::Mat(), Rt)) {
    return std::nullopt;
  }
  Eigen::Matrix4d T_current_reference;
  cv::cv2eigen(Rt, T_current_reference);
  return T_W_reference * Isometry(T_current_reference).inverse();
}

cv::Mat matOf(const o3d::core::Tensor& tensor, int type) {
  const o3d::core::Tensor t = tensor.Contiguous();
  return cv::Mat(static_cast<int>(t.GetShape(0)), static_cast<int>(t.GetShape(1)), type,
                 const_cast<void*>(t.GetDataPtr()))
      .clone();
}

// Frame-to-model tracking: raycast the grid at the last pose and align the new frame to that
// model view with OpenCV's odometry; integrate at the new pose.
Timing frameToModel(const std::vector<Frame>& frames, int factor) {
  auto grid = makeBlockGrid(0.01);
  cv::Ptr<cv::rgbd::RgbdICPOdometry> odometry;
  tessera::core::Trajectory estimate, truth;
  Isometry T_W_C = *frames.front().T_W_C_gt;
  o3d::core::Tensor blocks;
  double total = 0.0, raycast_ms = 0.0;
  int failures = 0;
  for (const Frame& frame : frames) {
    const ScaledFrame f = scaled(frame, factor);
    const auto start = Clock::now();
    if (!odometry) odometry = makeOdometry(f);
    if (blocks.NumElements() > 0) {
      const auto raycast_start = Clock::now();
      auto view =
          grid.RayCast(blocks, tensorIntrinsics(f), tensorPose(T_W_C.inverse()), f.width, f.height,
                       {"depth", "color"}, 1000.0f, 0.3f, 4.0f, 1.0f, kTruncVoxels);
      raycast_ms += msSince(raycast_start);
      OdometryImages model;
      model.depth = matOf(view["depth"], CV_32FC1) * 1e-3;
      model.depth.setTo(std::numeric_limits<float>::quiet_NaN(), model.depth <= 0.0f);
      cv::Mat colour = matOf(view["color"], CV_32FC3);
      colour.convertTo(colour, CV_8UC3, 255.0);
      cv::cvtColor(colour, model.grey, cv::COLOR_RGB2GRAY);
      const auto tracked = odometryStep(*odometry, model, odometryImages(f), T_W_C);
      failures += tracked ? 0 : 1;
      T_W_C = tracked.value_or(T_W_C);
    }
    blocks = integrateBlockGrid(grid, f, T_W_C);
    total += msSince(start);
    estimate[frame.timestamp_ns] = T_W_C;
    truth[frame.timestamp_ns] = *frame.T_W_C_gt;
  }
  const double n = static_cast<double>(frames.size());
  return {total / n, fmt::format("incl. integration, raycast {:.1f} ms; {}", raycast_ms / n,
                                 ateNote(estimate, truth, failures))};
}

// OpenCV's RgbdICPOdometry, frame to frame (what the first tracker did).
Timing opencvFrameToFrame(const std::vector<Frame>& frames, int factor) {
  cv::Ptr<cv::rgbd::RgbdICPOdometry> odometry;
  tessera::core::Trajectory estimate, truth;
  Isometry T_W_C = *frames.front().T_W_C_gt;
  OdometryImages previous;
  double total = 0.0;
  int failures = 0;
  for (const Frame& frame : frames) {
    const ScaledFrame f = scaled(frame, factor);
    const auto start = Clock::now();
    if (!odometry) odometry = makeOdometry(f);
    OdometryImages current = odometryImages(f);
    if (!previous.depth.empty()) {
      const auto tracked = odometryStep(*odometry, previous, current, T_W_C);
      failures += tracked ? 0 : 1;
      T_W_C = tracked.value_or(T_W_C);
    }
    previous = std::move(current);
    total += msSince(start);
    estimate[frame.timestamp_ns] = T_W_C;
    truth[frame.timestamp_ns] = *frame.T_W_C_gt;
  }
  return {total / static_cast<double>(frames.size()), ateNote(estimate, truth, failures)};
}

// tessera's own pipeline (tracking and integration stages in the flow graph) on the same
// frames, with the default configuration.
Timing tesseraPipeline(const std::vector<Frame>& frames, int threads) {
  tessera::bench::MemorySource source(frames, "frames in memory");
  tessera::pipeline::RunOptions options;
  options.out_dir = std::filesystem::temp_directory_path() / "tessera_fusion_options_bench";
  options.threads = threads;
  const auto summary = tessera::pipeline::runPipeline(
      source, tessera::pipeline::loadRunConfig(std::nullopt), options);
  double work_ms = 0.0;
  for (const auto& stage : summary.stages) {
    if (stage.name == "tracking" || stage.name == "integration") work_ms += stage.mean_ms;
  }
  return {1000.0 / summary.fps,
          fmt::format("tracking + integration {:.1f} ms of work per frame; ATE {:.1f} mm", work_ms,
                      summary.ate ? summary.ate->rmse_m * 1e3 : 0.0)};
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Measures the tracking and TSDF options tessera chose between"};
  std::string source_path;
  std::size_t max_frames = 0;
  int threads = 2;
  bool skip_options = false;
  std::string intrinsics_spec;
  std::optional<double> depth_units_per_m;
  app.add_option("SOURCE", source_path, "Dataset folder or .oni recording with ground truth");
  app.add_option("--intrinsics", intrinsics_spec, "fx,fy,cx,cy as given to tessera run");
  app.add_option("--depth-scale", depth_units_per_m, "Raw depth units per metre");
  app.add_option("--max-frames", max_frames, "Frames to use (0: all)");
  app.add_option("--threads", threads, "Threads for OpenMP, OpenCV and the flow graph")
      ->check(CLI::PositiveNumber);
  app.add_flag("--skip-options", skip_options, "Only the comparison with the plain Open3D loop");
  CLI11_PARSE(app, argc, argv);
  omp_set_num_threads(threads);
  cv::setNumThreads(threads);
  tessera::core::initLogging("warn");
  o3d::utility::SetVerbosityLevel(o3d::utility::VerbosityLevel::Error);

  try {
    std::optional<tessera::core::Intrinsics> intrinsics;
    if (!intrinsics_spec.empty()) intrinsics = tessera::core::parseIntrinsicsSpec(intrinsics_spec);
    const auto frames = tessera::bench::loadFrames(source_path, max_frames, /*need_truth=*/true,
                                                   intrinsics, depth_units_per_m);
    fmt::print("{} frames of {}x{} from {}, {} threads\n", frames.size(),
               frames.front().intrinsics.width, frames.front().intrinsics.height,
               tessera::bench::resolvedSource(source_path), threads);
    if (!skip_options) {
      for (const double voxel : {0.01, 0.02}) {
        fmt::print(
            "\nTSDF integration at ground-truth poses ({:.0f} cm voxels, {:.0f} cm truncation)\n",
            voxel * 100, voxel * 300);
        for (int factor : {1, 2}) {
          const std::string res = factor == 1 ? "640x480" : "320x240";
          printRow("ScalableTSDFVolume " + res, scalableIntegration(frames, factor, voxel));
          const auto [integrate, raycast] = blockGridIntegration(frames, factor, voxel);
          printRow("VoxelBlockGrid " + res, integrate);
          printRow("VoxelBlockGrid raycast " + res, raycast);
        }
      }
      fmt::print("\nTracking (ATE against the ground truth)\n");
      for (int factor : {1, 2}) {
        const std::string res = factor == 1 ? "640x480" : "320x240";
        printRow("OpenCV RgbdICPOdometry frame-to-frame " + res,
                 opencvFrameToFrame(frames, factor));
        printRow("frame-to-model (VoxelBlockGrid raycast + odometry) " + res,
                 frameToModel(frames, factor));
      }
    }
    fmt::print("\nTracking + fusion, whole run over the frames in memory\n");
    const auto loop = tessera::bench::plainOpen3dLoop(frames, tessera::fusion::TsdfConfig{});
    std::string note = loop.ate_mm ? fmt::format("ATE {:.1f} mm over {} poses", *loop.ate_mm,
                                                 loop.ate_poses)
                                   : std::string("ATE: too few poses");
    if (loop.odometry_failures > 0) {
      note += fmt::format("; {} odometry failures", loop.odometry_failures);
    }
    const Timing plain{loop.ms_per_frame, note};
    const Timing ours = tesseraPipeline(frames, threads);
    printRow("plain Open3D loop (legacy odometry + ScalableTSDFVolume)", plain);
    printRow("tessera pipeline (default config)", ours);
    fmt::print("  tessera is {:.1f}x faster than the plain Open3D loop\n",
               plain.ms_per_frame / ours.ms_per_frame);
  } catch (const std::exception& e) {
    fmt::print(stderr, "fusion_options_bench: {}\n", e.what());
    return 1;
  }
  return 0;
}
