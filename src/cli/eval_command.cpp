#include "eval_command.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include "tessera/core/error.h"
#include "tessera/eval/reuse_sheet.h"
#include "tessera/eval/run_evaluation.h"

namespace tessera::cli {

namespace {

// One line per figure on stdout, for people and scripts alike; the per-plane and per-texture
// lists stay in report.json.
void printFigures(const nlohmann::json& figures) {
  for (const auto& [key, value] : figures.items()) {
    if (key != "planes" && key != "textures") fmt::print("{}: {}\n", key, value.dump());
  }
}

}  // namespace

CLI::App* addEvalCommand(CLI::App& app, EvalArguments& args) {
  CLI::App* eval = app.add_subcommand(
      "eval",
      "Measure a run (OUT of tessera run): against ground truth (a recording's .gt.json), and/or "
      "by rendering its textured patches into the captured frames (--frames SOURCE)");
  eval->add_option("RUN_DIR", args.run_dir, "Output folder of tessera run")
      ->required()
      ->check(CLI::ExistingDirectory);
  eval->add_option("GT", args.ground_truth, "Ground-truth file, e.g. recordings/office.gt.json")
      ->check(CLI::ExistingFile);
  eval->add_option("--frames", args.frames,
                   "View PSNR, SSIM and detail: render patches.obj and mesh.ply at the run's poses "
                   "into the frames "
                   "of this source (the one the run read, with the same --depth-scale and "
                   "--intrinsics) and compare over the same pixels");
  eval->add_option("--map", args.map_file,
                   "With --frames: the map file in RUN_DIR rendered as the patches: patches.obj, "
                   "map.obj or map.glb (read with tinygltf)")
      ->capture_default_str();
  eval->add_option("--unmatched", args.unmatched_run,
                   "With --frames: the same run made with matching off (match.enabled: false); its "
                   "map is rendered over the same pixels, and the view PSNR, SSIM and detail the "
                   "reuses lose against it are reported, overall and per reused, tiled or layered "
                   "patch")
      ->check(CLI::ExistingDirectory);
  eval->add_option("--save", args.save_dir,
                   "With --frames: write render | captured | difference PNGs of a few views here");
  eval->add_option("--max-views", args.max_views,
                   "With --frames: training views to score, spread evenly (held-out views "
                   "likewise)")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  eval->add_option("--edge-margin", args.edge_margin_px,
                   "With --frames: pixels within this many pixels of a depth discontinuity (a "
                   "pixel whose captured depth disagrees with the map) are not compared")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  eval->add_option("--pose-time", args.pose_time,
                   "With --frames: render each view at the pose of its colour image's time "
                   "(interpolated; sources without colour time stamps fall back to depth) or of "
                   "its depth image's")
      ->check(CLI::IsMember({"colour", "depth"}))
      ->capture_default_str();
  eval->add_option("--plane-offset-m", args.plane_offset_m,
                   "With GT: a patch matches a true plane with its centroid this close to it "
                   "(metres) ...")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  eval->add_option("--plane-normal-deg", args.plane_normal_deg,
                   "... and its normal this close (degrees); wider bounds suit a large map "
                   "tracked to centimetres")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  addSourceOptions(*eval, args.source_args);
  return eval;
}

int evalCommand(const EvalArguments& args) {
  if (args.ground_truth.empty() && args.frames.empty()) {
    spdlog::error("eval: give a ground-truth file (GT), --frames SOURCE, or both");
    return 2;
  }
  try {
    if (!args.ground_truth.empty()) {
      eval::PlaneEvaluationOptions planes;
      planes.max_offset_m = args.plane_offset_m;
      planes.max_normal_deg = args.plane_normal_deg;
      printFigures(eval::evaluateRun(args.run_dir, args.ground_truth, planes));
    }
    if (!args.frames.empty()) {
      const std::unique_ptr<core::FrameSource> source = openSource(args.frames, args.source_args);
      eval::ViewEvaluationOptions options;
      options.max_views = args.max_views;
      options.edge_margin_px = args.edge_margin_px;
      options.colour_time = args.pose_time == "colour";
      options.save_dir = args.save_dir;
      options.map_file = args.map_file;
      options.unmatched_run = args.unmatched_run;
      printFigures(eval::evaluateRunViews(args.run_dir, *source, options));
    }
    // Needs no ground truth: written for every run evaluated.
    if (const int reuses = eval::writeReuseSheet(args.run_dir); reuses > 0) {
      fmt::print("reuse sheet: {} ({} reuses)\n",
                 (std::filesystem::path(args.run_dir) / "reuse_sheet.png").string(), reuses);
    }
    spdlog::info("figures written into {}/report.json", args.run_dir);
    return 0;
  } catch (const core::Error& e) {
    spdlog::error("{}", e.what());
    return 1;
  }
}

}  // namespace tessera::cli
