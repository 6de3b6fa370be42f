// The measurements behind the tracking and TSDF choices in docs/ARCHITECTURE.md. Every option
// runs over the same frames, held in memory so decoding is not timed:
//   - TSDF integration at ground-truth poses: Open3D's ScalableTSDFVolume (legacy) and
//     VoxelBlockGrid (tensor, CPU), at full and half depth resolution, plus VoxelBlockGrid's
//     raycast (what frame-to-model tracking needs);
//   - tracking: OpenCV's RgbdICPOdometry frame to frame, and frame-to-model (VoxelBlockGrid
//     raycast + Open3D's tensor point-to-plane odometry), at full and half resolution, with the
//     ATE of each trajectory.
//
//   fusion_options_bench [SOURCE] [--max-frames N] [--threads N]
#include <chrono>
#include <filesystem>
#include <functional>

#include <fmt/format.h>
#include <omp.h>
#include <CLI/CLI.hpp>
#include <open3d/camera/PinholeCameraIntrinsic.h>
#include <open3d/core/EigenConverter.h>
#include <open3d/geometry/Image.h>
#include <open3d/geometry/RGBDImage.h>
#include <open3d/pipelines/integration/ScalableTSDFVolume.h>
#include <open3d/t/geometry/Image.h>
#include <open3d/t/geometry/Utility.h>
#include <open3d/t/geometry/VoxelBlockGrid.h>
#include <open3d/utility/Logging.h>
#include <opencv2/core/eigen.hpp>
#include <opencv2/core/utility.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/rgbd.hpp>

#include "bench_frames.h"
#include "tessera/eval/trajectory.h"

namespace {

namespace o3d = open3d;
using tessera::core::Frame;
using tessera::core::Isometry;
using Clock = std::chrono::steady_clock;

double msSince(Clock::time_point start) {
  return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

// A frame at `scale` of its resolution: depth by nearest neighbour (no mixing across edges),
// colour by area averaging.
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
  out.cx = (k.cx + 0.5) / factor - 0.5;
  out.cy = (k.cy + 0.5) / factor - 0.5;
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

extern int odometry_failures;

void printRow(const std::string& name, const Timing& t) {
  fmt::print("  {:<58} {:8.2f} ms/frame {:7.1f} frames/s  {}{}\n", name, t.ms_per_frame,
             1000.0 / t.ms_per_frame, t.note,
             odometry_failures > 0 ? fmt::format("; {} odometry failures", odometry_failures) : "");
  odometry_failures = 0;
}

std::string ateNote(const tessera::eval::Trajectory& estimate,
                    const tessera::eval::Trajectory& truth) {
  const auto ate = tessera::eval::absoluteTrajectoryError(estimate, truth);
  return ate ? fmt::format("ATE {:.1f} mm over {} poses", ate->rmse_m * 1e3, ate->pairs)
             : std::string("ATE: too few poses");
}

Timing scalableIntegration(const std::vector<Frame>& frames, int factor) {
  o3d::pipelines::integration::ScalableTSDFVolume volume(
      0.01, 0.04, o3d::pipelines::integration::TSDFVolumeColorType::RGB8, 16);
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

o3d::t::geometry::VoxelBlockGrid makeBlockGrid() {
  return o3d::t::geometry::VoxelBlockGrid(
      {"tsdf", "weight", "color"}, {o3d::core::Float32, o3d::core::UInt16, o3d::core::UInt16},
      {{1}, {1}, {3}}, 0.01f, 16, 20000);
}

constexpr float kTruncVoxels = 4.0f;  // 4 cm at 1 cm voxels, as the ScalableTSDFVolume runs

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

std::pair<Timing, Timing> blockGridIntegration(const std::vector<Frame>& frames, int factor) {
  auto grid = makeBlockGrid();
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
  auto odometry = cv::rgbd::RgbdICPOdometry::create(K, 0.3f, 4.0f, 0.07f);
  if (const char* levels = std::getenv("LEVELS")) {
    std::vector<int> iters{7, 7, 7, 10};
    iters.erase(iters.begin(), iters.begin() + (4 - std::atoi(levels)));
    odometry->setIterationCounts(cv::Mat(iters).clone());
    odometry->setMinGradientMagnitudes(cv::Mat(std::vector<float>(iters.size(), 10.f)).clone());
  }
  return odometry;
}

int odometry_failures = 0;  // reset per option; failures keep the previous pose

// The pose of `current` from the odometry that maps `reference` points (seen from
// T_W_reference) into `current`; nothing when the odometry fails.
std::optional<Isometry> odometryStep(cv::rgbd::RgbdICPOdometry& odometry, const OdometryImages& reference,
                      const OdometryImages& current, const Isometry& T_W_reference,
                      const Isometry& guess_T_reference_current = Isometry::Identity()) {
  cv::Mat Rt, init;
  cv::eigen2cv(Eigen::Matrix4d(guess_T_reference_current.inverse().matrix()), init);
  if (!odometry.compute(reference.grey, reference.depth, cv::Mat(), current.grey, current.depth,
                        cv::Mat(), Rt, init)) {
    ++odometry_failures;
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
  auto grid = makeBlockGrid();
  cv::Ptr<cv::rgbd::RgbdICPOdometry> odometry;
  tessera::eval::Trajectory estimate, truth;
  Isometry T_W_C = *frames.front().T_W_C_gt;
  o3d::core::Tensor blocks;
  double total = 0.0, raycast_ms = 0.0;
  for (const Frame& frame : frames) {
    const ScaledFrame f = scaled(frame, factor);
    const auto start = Clock::now();
    if (!odometry) odometry = makeOdometry(f);
    if (blocks.NumElements() > 0) {
      const auto raycast_start = Clock::now();
      auto view = grid.RayCast(blocks, tensorIntrinsics(f), tensorPose(T_W_C.inverse()), f.width,
                               f.height, {"depth", "color"}, 1000.0f, 0.3f, 4.0f, 1.0f,
                               kTruncVoxels);
      raycast_ms += msSince(raycast_start);
      OdometryImages model;
      model.depth = matOf(view["depth"], CV_32FC1) * 1e-3;
      model.depth.setTo(std::numeric_limits<float>::quiet_NaN(), model.depth <= 0.0f);
      cv::Mat colour = matOf(view["color"], CV_32FC3);
      colour.convertTo(colour, CV_8UC3, 255.0);
      cv::cvtColor(colour, model.grey, cv::COLOR_RGB2GRAY);
      T_W_C = odometryStep(*odometry, model, odometryImages(f), T_W_C).value_or(T_W_C);
    }
    blocks = integrateBlockGrid(grid, f, T_W_C);
    total += msSince(start);
    estimate[frame.timestamp_ns] = T_W_C;
    truth[frame.timestamp_ns] = *frame.T_W_C_gt;
  }
  const double n = static_cast<double>(frames.size());
  return {total / n, fmt::format("incl. integration, raycast {:.1f} ms; {}", raycast_ms / n,
                                 ateNote(estimate, truth))};
}

// OpenCV's RgbdICPOdometry, frame to frame (what the first tracker did).
Timing opencvFrameToFrame(const std::vector<Frame>& frames, int factor) {
  cv::Ptr<cv::rgbd::RgbdICPOdometry> odometry;
  tessera::eval::Trajectory estimate, truth;
  Isometry T_W_C = *frames.front().T_W_C_gt;
  OdometryImages previous;
  Isometry velocity = Isometry::Identity();
  Isometry previous_gt;
  double total = 0.0;
  for (const Frame& frame : frames) {
    const ScaledFrame f = scaled(frame, factor);
    const auto start = Clock::now();
    if (!odometry) odometry = makeOdometry(f);
    OdometryImages current = odometryImages(f);
    if (!previous.depth.empty()) {
      const Isometry guess = std::getenv("VELOCITY") ? velocity : Isometry::Identity();
      const Isometry T_W_new = odometryStep(*odometry, previous, current, T_W_C, guess).value_or(T_W_C);
      velocity = T_W_C.inverse() * T_W_new;
      T_W_C = T_W_new;
      if (std::getenv("DEBUG")) {
        const Isometry gt_step = previous_gt.inverse() * *frame.T_W_C_gt;
        const Isometry err = gt_step.inverse() * velocity;
        fmt::print("{} step {:.1f} mm err {:.2f} mm {:.3f} deg\n", frame.index, gt_step.translation().norm()*1e3,
                   err.translation().norm() * 1e3,
                   Eigen::AngleAxisd(err.rotation()).angle() * 180 / M_PI);
      }
    }
    previous = std::move(current);
    previous_gt = *frame.T_W_C_gt;
    total += msSince(start);
    estimate[frame.timestamp_ns] = T_W_C;
    truth[frame.timestamp_ns] = *frame.T_W_C_gt;
  }
  return {total / static_cast<double>(frames.size()), ateNote(estimate, truth)};
}

// Frame-to-keyframe: each frame is aligned to the last keyframe, which is replaced once the
// camera has moved `keyframe_m` or turned `keyframe_deg` from it. Drift then grows per
// keyframe rather than per frame.
Timing opencvFrameToKeyframe(const std::vector<Frame>& frames, int factor, double keyframe_m,
                             double keyframe_deg) {
  cv::Ptr<cv::rgbd::RgbdICPOdometry> odometry;
  tessera::eval::Trajectory estimate, truth;
  Isometry T_W_C = *frames.front().T_W_C_gt;
  Isometry T_W_key = T_W_C;
  OdometryImages key;
  double total = 0.0;
  int keyframes = 0;
  for (const Frame& frame : frames) {
    const ScaledFrame f = scaled(frame, factor);
    const auto start = Clock::now();
    if (!odometry) odometry = makeOdometry(f);
    OdometryImages current = odometryImages(f);
    if (!key.depth.empty()) {
      // Start from the last frame's pose relative to the key.
      T_W_C = odometryStep(*odometry, key, current, T_W_key, T_W_key.inverse() * T_W_C)
                  .value_or(T_W_C);
    }
    const Isometry T_key_C = T_W_key.inverse() * T_W_C;
    const double angle_deg = Eigen::AngleAxisd(T_key_C.rotation()).angle() * 180.0 / M_PI;
    if (key.depth.empty() || T_key_C.translation().norm() > keyframe_m ||
        angle_deg > keyframe_deg) {
      key = std::move(current);
      T_W_key = T_W_C;
      ++keyframes;
    }
    total += msSince(start);
    estimate[frame.timestamp_ns] = T_W_C;
    truth[frame.timestamp_ns] = *frame.T_W_C_gt;
  }
  return {total / static_cast<double>(frames.size()),
          fmt::format("{} keyframes; {}", keyframes, ateNote(estimate, truth))};
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Measures the tracking and TSDF options tessera chose between"};
  std::string source_path;
  std::size_t max_frames = 0;
  int threads = 2;
  app.add_option("SOURCE", source_path, "Dataset folder or .oni recording with ground truth");
  app.add_option("--max-frames", max_frames, "Frames to use (0: all)");
  app.add_option("--threads", threads, "OpenMP/OpenCV threads")->check(CLI::PositiveNumber);
  CLI11_PARSE(app, argc, argv);
  omp_set_num_threads(threads);
  o3d::utility::SetVerbosityLevel(o3d::utility::VerbosityLevel::Error);
  cv::setNumThreads(threads);

  try {
    const auto frames = tessera::bench::loadFrames(source_path, max_frames, /*need_truth=*/true);
    fmt::print("{} frames of {}x{} from {}, {} threads\n\n", frames.size(),
               frames.front().intrinsics.width, frames.front().intrinsics.height,
               tessera::bench::resolvedSource(source_path), threads);
    fmt::print("TSDF integration at ground-truth poses (1 cm voxels, 4 cm truncation)\n");
    for (int factor : {1, 2}) {
      if (std::getenv("TRACK_ONLY")) break;
      const std::string res = factor == 1 ? "640x480" : "320x240";
      printRow("ScalableTSDFVolume " + res, scalableIntegration(frames, factor));
      const auto [integrate, raycast] = blockGridIntegration(frames, factor);
      printRow("VoxelBlockGrid " + res, integrate);
      printRow("VoxelBlockGrid raycast " + res, raycast);
    }
    fmt::print("\nTracking (ATE against the ground truth)\n");
    for (int factor : {1, 2}) {
      const std::string res = factor == 1 ? "640x480" : "320x240";
      printRow("OpenCV RgbdICPOdometry frame-to-frame " + res, opencvFrameToFrame(frames, factor));
      printRow("OpenCV RgbdICPOdometry frame-to-keyframe " + res,
               opencvFrameToKeyframe(frames, factor, 0.05, 5.0));
      if (std::getenv("TRACK_ONLY")) continue;
      printRow("frame-to-model (VoxelBlockGrid raycast + ICP) " + res,
               frameToModel(frames, factor));
    }
  } catch (const std::exception& e) {
    fmt::print(stderr, "fusion_options_bench: {}\n", e.what());
    return 1;
  }
  return 0;
}
