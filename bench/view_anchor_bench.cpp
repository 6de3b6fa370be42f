// View PSNR (docs/METRICS.md) of a run beside the two Open3D anchors users know, on the same
// frames, poses and pixels:
//   - patches:         the run's textured patches (RUN_DIR/patches.obj);
//   - mesh:            the run's vertex-coloured TSDF mesh (RUN_DIR/mesh.ply);
//   - open3d_1cm:      the plain Open3D loop: ScalableTSDFVolume (RGB8, --voxel-m voxels,
//                      truncation 4 voxels, depth cut at 4 m) over every training frame at the
//                      run's pose, then ExtractTriangleMesh() with its vertex colours;
//   - open3d_colormap: that mesh after Open3D's colour map optimisation (Zhou & Koltun 2014,
//                      RunRigidOptimizer) over up to --colour-map-max-images training frames.
// Training frames are those with a pose in RUN_DIR/trajectory.txt that report.json's
// holdout_every does not hold out; held-out frames are neither integrated nor optimised over, and
// are scored separately. Prints a table, then one `json: {...}` line for scripts.
//
//   tessera run SOURCE --holdout-every 5 --out RUN_DIR
//   view_anchor_bench RUN_DIR SOURCE [--intrinsics fx,fy,cx,cy] [--depth-scale UNITS_PER_M]
//       [--voxel-m 0.01] [--colour-map-iterations 100] [--colour-map-max-images 60]
//       [--max-views 20] [--save DIR] [--threads 2]
//
// Open3D runs on OpenMP, whose threads spin at every barrier: when another job holds a core,
// integration and colour map optimisation run about 10x slower in wall and CPU time alike. On a
// shared machine, run with OMP_WAIT_POLICY=passive in the environment (read when OpenMP loads,
// before main) or --threads 1.
#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <omp.h>
#include <open3d/camera/PinholeCameraIntrinsic.h>
#include <open3d/camera/PinholeCameraTrajectory.h>
#include <open3d/geometry/Image.h>
#include <open3d/geometry/RGBDImage.h>
#include <open3d/geometry/TriangleMesh.h>
#include <open3d/pipelines/color_map/RigidOptimizer.h>
#include <open3d/pipelines/integration/ScalableTSDFVolume.h>
#include <open3d/utility/Logging.h>
#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "bench_frames.h"
#include "tessera/core/error.h"
#include "tessera/core/log.h"
#include "tessera/core/trajectory.h"
#include "tessera/eval/view_evaluation.h"
#include "tessera/eval/view_render.h"

namespace {

namespace o3d = open3d;
namespace fs = std::filesystem;
using tessera::core::Frame;
using tessera::core::Isometry;
using Clock = std::chrono::steady_clock;

// The plain Open3D loop's settings: sdf_trunc 0.04 m and depth_trunc 4 m, as users copy them
// from Open3D's RGB-D integration examples.
constexpr double kTruncationVoxels = 4.0;  // sdf_trunc 0.04 m at 1 cm voxels
constexpr double kDepthTruncM = 4.0;
constexpr double kDepthScale = 1000.0;  // frames carry millimetres, whatever the source's units
constexpr std::int64_t kMaxPoseGapNs = 1'000'000;  // as eval::evaluateViews: within 1 ms

struct Arguments {
  std::string run_dir;
  std::string source;
  std::string intrinsics;
  double depth_units_per_m = 0.0;  // 0: the source's own
  double voxel_m = 0.01;
  int colour_map_iterations = 100;
  int colour_map_max_images = 60;
  int max_views = 20;
  std::string save_dir;
  int threads = 2;
};

double secondsSince(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

// Wall time, and the process's CPU time over all threads: how much work the step was, where
// the machine is shared (OpenMP threads spinning at barriers count too; see the top).
struct Stopwatch {
  Clock::time_point wall = Clock::now();
  std::clock_t cpu = std::clock();
  double wallSeconds() const { return secondsSince(wall); }
  double cpuSeconds() const {
    return static_cast<double>(std::clock() - cpu) / static_cast<double>(CLOCKS_PER_SEC);
  }
};

std::optional<Isometry> poseAt(const tessera::core::Trajectory& poses, std::int64_t timestamp_ns) {
  auto it = poses.lower_bound(timestamp_ns - kMaxPoseGapNs);
  if (it == poses.end() || it->first > timestamp_ns + kMaxPoseGapNs) return std::nullopt;
  return it->second;
}

// report.json's holdout_every; 0 (none) when the key is missing or not an integer.
int readHoldoutEvery(const fs::path& report_path) {
  std::ifstream in(report_path);
  if (!in) throw tessera::core::Error(fmt::format("{}: cannot be read", report_path.string()));
  nlohmann::json report;
  try {
    in >> report;
  } catch (const nlohmann::json::exception& e) {
    throw tessera::core::Error(fmt::format("{}: not JSON: {}", report_path.string(), e.what()));
  }
  const auto every = report.find("holdout_every");
  if (every == report.end() || !every->is_number_integer()) return 0;
  return every->get<int>();
}

o3d::geometry::Image open3dImage(const cv::Mat& mat) {
  o3d::geometry::Image image;
  image.Prepare(mat.cols, mat.rows, mat.channels(), static_cast<int>(mat.elemSize1()));
  const std::size_t row_bytes = static_cast<std::size_t>(mat.cols) * mat.elemSize();
  for (int v = 0; v < mat.rows; ++v) {
    std::memcpy(image.data_.data() + static_cast<std::size_t>(v) * row_bytes, mat.ptr(v),
                row_bytes);
  }
  return image;
}

o3d::camera::PinholeCameraIntrinsic open3dIntrinsic(const tessera::core::Intrinsics& k) {
  return {k.width, k.height, k.fx, k.fy, k.cx, k.cy};
}

// A training frame as Open3D takes it: RGB8 colour and depth in metres (float), cut at 4 m.
struct TrainingView {
  const Frame* frame = nullptr;
  Isometry T_W_C;
  std::shared_ptr<o3d::geometry::RGBDImage> rgbd;
};

struct Anchor {
  std::shared_ptr<o3d::geometry::TriangleMesh> mesh;
  double seconds = 0.0;
  double cpu_seconds = 0.0;
  std::set<std::uint64_t> frames;  // indices of the training frames it was built from
};

Anchor integrate(std::vector<TrainingView>& views, double voxel_m) {
  const Stopwatch stopwatch;
  o3d::pipelines::integration::ScalableTSDFVolume volume(
      voxel_m, voxel_m * kTruncationVoxels, o3d::pipelines::integration::TSDFVolumeColorType::RGB8);
  for (TrainingView& view : views) {
    view.rgbd = o3d::geometry::RGBDImage::CreateFromColorAndDepth(
        open3dImage(view.frame->rgb), open3dImage(view.frame->depth_mm), kDepthScale, kDepthTruncM,
        /*convert_rgb_to_intensity=*/false);
    // Open3D's extrinsic maps world to camera.
    volume.Integrate(*view.rgbd, open3dIntrinsic(view.frame->intrinsics),
                     view.T_W_C.inverse().matrix());
  }
  Anchor anchor;
  anchor.mesh = volume.ExtractTriangleMesh();
  anchor.seconds = stopwatch.wallSeconds();
  anchor.cpu_seconds = stopwatch.cpuSeconds();
  for (const TrainingView& view : views) anchor.frames.insert(view.frame->index);
  return anchor;
}

// Up to max_images views spread evenly over all of them.
std::vector<const TrainingView*> evenSubset(const std::vector<TrainingView>& views,
                                            std::size_t max_images) {
  std::vector<const TrainingView*> subset;
  const std::size_t n = std::min(views.size(), max_images);
  for (std::size_t i = 0; i < n; ++i) subset.push_back(&views[i * views.size() / n]);
  return subset;
}

Anchor optimiseColourMap(const o3d::geometry::TriangleMesh& mesh,
                         const std::vector<TrainingView>& views, int iterations,
                         std::size_t max_images) {
  Anchor anchor;
  std::vector<o3d::geometry::RGBDImage> images;
  o3d::camera::PinholeCameraTrajectory trajectory;
  for (const TrainingView* view : evenSubset(views, max_images)) {
    images.push_back(*view->rgbd);
    anchor.frames.insert(view->frame->index);
    o3d::camera::PinholeCameraParameters camera;
    camera.intrinsic_ = open3dIntrinsic(view->frame->intrinsics);
    camera.extrinsic_ = view->T_W_C.inverse().matrix();
    trajectory.parameters_.push_back(camera);
  }
  o3d::pipelines::color_map::RigidOptimizerOption option;
  option.maximum_iteration_ = iterations;
  // Open3D's default (2.5 m) would leave the vertices between 2.5 m and the integration's 4 m
  // cut to its nearest-neighbour fill; every vertex of the mesh was seen within 4 m.
  option.maximum_allowable_depth_ = kDepthTruncM;
  const Stopwatch stopwatch;
  auto [optimised, cameras] =
      o3d::pipelines::color_map::RunRigidOptimizer(mesh, images, trajectory, option);
  anchor.seconds = stopwatch.wallSeconds();
  anchor.cpu_seconds = stopwatch.cpuSeconds();
  anchor.mesh = std::make_shared<o3d::geometry::TriangleMesh>(std::move(optimised));
  return anchor;
}

// Open3D keeps vertex colours in [0, 1]; the renderer takes [0, 255].
tessera::eval::RenderMesh renderMesh(const o3d::geometry::TriangleMesh& mesh) {
  tessera::eval::RenderMesh out;
  out.vertices.reserve(mesh.vertices_.size());
  for (const Eigen::Vector3d& v : mesh.vertices_) out.vertices.push_back(v.cast<float>());
  out.triangles.assign(mesh.triangles_.begin(), mesh.triangles_.end());
  out.colours.reserve(mesh.vertex_colors_.size());
  for (const Eigen::Vector3d& c : mesh.vertex_colors_) {
    out.colours.push_back((c * 255.0).cast<float>());
  }
  if (out.colours.size() != out.vertices.size()) {
    throw tessera::core::Error("Open3D mesh without a colour per vertex");
  }
  return out;
}

nlohmann::json orNull(std::optional<double> value) {
  return value ? nlohmann::json(*value) : nlohmann::json(nullptr);
}

std::string cell(std::optional<double> value, const char* format) {
  return value ? fmt::format(fmt::runtime(format), *value) : std::string("-");
}

std::optional<double> difference(std::optional<double> a, std::optional<double> b) {
  if (!a || !b) return std::nullopt;
  return *a - *b;
}

int run(const Arguments& args) {
  const fs::path run_dir = args.run_dir;
  if (!fs::is_directory(run_dir)) {
    throw tessera::core::Error(fmt::format("{}: no such run folder", args.run_dir));
  }
  const int holdout_every = readHoldoutEvery(run_dir / "report.json");
  const tessera::core::Trajectory poses =
      tessera::core::readTumTrajectory(run_dir / "trajectory.txt");
  const tessera::eval::RenderMesh patches = tessera::eval::readTexturedObj(run_dir / "patches.obj");
  const tessera::eval::RenderMesh run_mesh = tessera::eval::readColouredPly(run_dir / "mesh.ply");

  std::optional<tessera::core::Intrinsics> intrinsics;
  if (!args.intrinsics.empty()) intrinsics = tessera::core::parseIntrinsicsSpec(args.intrinsics);
  std::optional<double> depth_units_per_m;
  if (args.depth_units_per_m > 0.0) depth_units_per_m = args.depth_units_per_m;
  const std::vector<Frame> frames = tessera::bench::loadFrames(args.source, 0, /*need_truth=*/false,
                                                               intrinsics, depth_units_per_m);

  std::vector<TrainingView> training;
  std::size_t held_out = 0;
  for (const Frame& frame : frames) {
    if (tessera::core::isHeldOut(frame.index, holdout_every)) {
      ++held_out;
      continue;
    }
    if (const auto T_W_C = poseAt(poses, frame.timestamp_ns)) {
      training.push_back({&frame, *T_W_C, nullptr});
    }
  }
  if (training.empty()) {
    throw tessera::core::Error(fmt::format("{}: no training frame of {} has a pose in {}",
                                           args.run_dir, args.source,
                                           (run_dir / "trajectory.txt").string()));
  }
  fmt::print("{} frames from {}: {} training frames with a pose, {} held out (holdout_every {})\n",
             frames.size(), args.source, training.size(), held_out, holdout_every);

  const Anchor plain = integrate(training, args.voxel_m);
  fmt::print("open3d_1cm: integrated {} frames and extracted {} vertices in {:.1f} s\n",
             plain.frames.size(), plain.mesh->vertices_.size(), plain.seconds);
  std::fflush(stdout);  // the colour map optimisation can take minutes
  std::optional<Anchor> colour_mapped;
  if (args.colour_map_iterations > 0) {
    colour_mapped = optimiseColourMap(*plain.mesh, training, args.colour_map_iterations,
                                      static_cast<std::size_t>(args.colour_map_max_images));
    fmt::print("open3d_colormap: {} iterations over {} of {} training frames in {:.1f} s\n",
               args.colour_map_iterations, colour_mapped->frames.size(), training.size(),
               colour_mapped->seconds);
  }
  // The training frames' images are no longer needed; the views below read the frames.
  for (TrainingView& view : training) view.rgbd.reset();

  const tessera::eval::RenderMesh plain_mesh = renderMesh(*plain.mesh);
  std::optional<tessera::eval::RenderMesh> colour_mapped_mesh;
  if (colour_mapped) colour_mapped_mesh = renderMesh(*colour_mapped->mesh);
  std::vector<tessera::eval::ViewModel> models = {
      {"patches", &patches}, {"mesh", &run_mesh}, {"open3d_1cm", &plain_mesh}};
  if (colour_mapped_mesh) models.push_back({"open3d_colormap", &*colour_mapped_mesh});

  tessera::eval::ViewEvaluationOptions options;
  options.max_views = args.max_views;
  options.holdout_every = holdout_every;
  options.save_dir = args.save_dir;
  tessera::bench::MemorySource source(frames, args.source);
  const auto start = Clock::now();
  const tessera::eval::ViewEvaluation evaluation =
      tessera::eval::evaluateViews(models, source, poses, options);
  const double evaluation_s = secondsSince(start);

  fmt::print(
      "\nView PSNR over the pixels every model covers ({} training views, {} pixels; {} "
      "held-out views, {} pixels; {:.1f} s)\n",
      evaluation.viewCount(false), evaluation.pixels(false), evaluation.viewCount(true),
      evaluation.pixels(true), evaluation_s);
  fmt::print("  {:<16} {:>9} {:>12} {:>17} {:>20} {:>6} {:>7} {:>7} {:>7} {:>9}\n", "model",
             "train dB", "held-out dB", "train vs patches", "held-out vs patches", "SSIM", "detail",
             "corr", "energy", "vertices");
  nlohmann::json json_models = nlohmann::json::object();
  for (std::size_t m = 0; m < models.size(); ++m) {
    const auto train = evaluation.meanPsnr(m, false);
    const auto held = evaluation.meanPsnr(m, true);
    const auto train_delta = difference(train, evaluation.meanPsnr(0, false));
    const auto held_delta = difference(held, evaluation.meanPsnr(0, true));
    // Over the training views, as view PSNR's train column.
    using tessera::eval::ImageSimilarity;
    const auto ssim = evaluation.mean(m, false, &ImageSimilarity::ssim);
    const auto detail = evaluation.mean(m, false, &ImageSimilarity::detail);
    const auto correlation = evaluation.mean(m, false, &ImageSimilarity::detail_correlation);
    const auto energy = evaluation.mean(m, false, &ImageSimilarity::detail_energy_ratio);
    const std::size_t vertices = models[m].mesh->vertices.size();
    fmt::print("  {:<16} {:>9} {:>12} {:>17} {:>20} {:>6} {:>7} {:>7} {:>7} {:>9}\n",
               models[m].name, cell(train, "{:.2f}"), cell(held, "{:.2f}"),
               cell(train_delta, "{:+.2f}"), cell(held_delta, "{:+.2f}"), cell(ssim, "{:.3f}"),
               cell(detail, "{:.3f}"), cell(correlation, "{:.3f}"), cell(energy, "{:.2f}"),
               vertices);
    json_models[models[m].name] = {{"psnr_mean", orNull(train)},
                                   {"psnr_holdout_mean", orNull(held)},
                                   {"delta_to_patches_db", orNull(train_delta)},
                                   {"delta_to_patches_holdout_db", orNull(held_delta)},
                                   {"ssim_mean", orNull(ssim)},
                                   {"detail_mean", orNull(detail)},
                                   {"detail_correlation_mean", orNull(correlation)},
                                   {"detail_energy_ratio_mean", orNull(energy)},
                                   {"vertices", vertices},
                                   {"triangles", models[m].mesh->triangles.size()}};
  }
  fmt::print("Time: open3d_1cm integration + mesh extraction {:.1f} s (CPU {:.1f} s)",
             plain.seconds, plain.cpu_seconds);
  if (colour_mapped) {
    fmt::print("; open3d_colormap optimisation {:.1f} s (CPU {:.1f} s; {} iterations, {} images)",
               colour_mapped->seconds, colour_mapped->cpu_seconds, args.colour_map_iterations,
               colour_mapped->frames.size());
  }
  fmt::print("\n");
  // Training views scored that the colour map saw: the others are new to it (though not to the
  // TSDF), which favours open3d_1cm in the training column when it subsampled.
  std::size_t colour_mapped_views = 0;
  if (colour_mapped) {
    for (const tessera::eval::ViewScore& view : evaluation.views) {
      if (!view.held_out && colour_mapped->frames.count(view.index) > 0) ++colour_mapped_views;
    }
    fmt::print("open3d_colormap saw {} of the {} training views scored\n", colour_mapped_views,
               evaluation.viewCount(false));
  }

  const nlohmann::json json = {
      {"run_dir", args.run_dir},
      {"source", args.source},
      {"frames", frames.size()},
      {"training_frames", training.size()},
      {"held_out_frames", held_out},
      {"holdout_every", holdout_every},
      {"voxel_m", args.voxel_m},
      {"views", evaluation.viewCount(false)},
      {"views_holdout", evaluation.viewCount(true)},
      {"pixels", evaluation.pixels(false)},
      {"pixels_holdout", evaluation.pixels(true)},
      {"integration_s", plain.seconds},
      {"integration_cpu_s", plain.cpu_seconds},
      {"colour_map_s",
       colour_mapped ? nlohmann::json(colour_mapped->seconds) : nlohmann::json(nullptr)},
      {"colour_map_cpu_s",
       colour_mapped ? nlohmann::json(colour_mapped->cpu_seconds) : nlohmann::json(nullptr)},
      {"colour_map_iterations", args.colour_map_iterations},
      {"colour_map_images", colour_mapped ? colour_mapped->frames.size() : std::size_t{0}},
      {"colour_map_scored_views", colour_mapped_views},
      {"models", json_models}};
  fmt::print("json: {}\n", json.dump());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "View PSNR of a run's patches and mesh beside Open3D's TSDF mesh and its colour map "
      "optimisation, on the same frames, poses and pixels"};
  Arguments args;
  app.add_option("RUN_DIR", args.run_dir, "Output folder of tessera run SOURCE")->required();
  app.add_option("SOURCE", args.source, "The dataset folder or .oni recording the run read")
      ->required();
  app.add_option("--intrinsics", args.intrinsics,
                 "Camera intrinsics 'fx,fy,cx,cy[,width,height]', as given to tessera run");
  app.add_option("--depth-scale", args.depth_units_per_m,
                 "Raw depth units per metre of a dataset folder, as given to tessera run")
      ->check(CLI::PositiveNumber);
  app.add_option("--voxel-m", args.voxel_m, "Open3D TSDF voxel size (truncation: 4 voxels)")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  app.add_option("--colour-map-iterations", args.colour_map_iterations,
                 "Colour map optimisation iterations (0: skip open3d_colormap)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  app.add_option("--colour-map-max-images", args.colour_map_max_images,
                 "Training frames the colour map optimisation uses at most, spread evenly")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  app.add_option("--max-views", args.max_views,
                 "Training views to score, spread evenly (held-out views likewise)")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  app.add_option("--save", args.save_dir, "Write render | captured | difference PNGs here");
  app.add_option("--threads", args.threads, "OpenMP threads for Open3D")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  CLI11_PARSE(app, argc, argv);
  omp_set_num_threads(args.threads);
  tessera::core::initLogging(std::getenv("TESSERA_LOG") ? std::getenv("TESSERA_LOG") : "warn");
  o3d::utility::SetVerbosityLevel(o3d::utility::VerbosityLevel::Error);

  try {
    return run(args);
  } catch (const tessera::core::Error& e) {
    fmt::print(stderr, "view_anchor_bench: {}\n", e.what());
    return 1;
  } catch (const std::exception& e) {
    // Open3D reports its errors as std::runtime_error.
    fmt::print(stderr, "view_anchor_bench: {}\n", e.what());
    return 1;
  }
}
