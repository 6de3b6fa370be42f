#include "tessera/eval/run_evaluation.h"

#include <algorithm>
#include <fstream>
#include <memory>
#include <optional>

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include "tessera/core/error.h"
#include "tessera/core/trajectory.h"
#include "tessera/eval/plane_evaluation.h"
#include "tessera/eval/reuse_cost.h"
#include "tessera/eval/texture_evaluation.h"
#include "tessera/fusion/mesh_colours.h"

namespace tessera::eval {

namespace {

// Sets `figures` in the report and writes it back.
void mergeIntoReport(const std::filesystem::path& report_path, nlohmann::json& report,
                     const nlohmann::json& figures) {
  for (const auto& [key, value] : figures.items()) report[key] = value;
  std::ofstream out(report_path);
  out << report.dump(2) << '\n';
  out.close();
  if (!out) throw core::Error(fmt::format("{}: cannot write (disk full?)", report_path.string()));
}

nlohmann::json readJson(const std::filesystem::path& path) {
  std::ifstream in(path);
  if (!in) throw core::Error(fmt::format("{}: cannot open", path.string()));
  nlohmann::json json = nlohmann::json::parse(in, nullptr, /*allow_exceptions=*/false);
  if (json.is_discarded()) throw core::Error(fmt::format("{}: not valid JSON", path.string()));
  return json;
}

core::Trajectory groundTruthTrajectory(const nlohmann::json& gt) {
  core::Trajectory trajectory;
  for (const auto& frame : gt.value("frames", nlohmann::json::array())) {
    if (!frame.contains("T_W_C")) continue;
    const auto p = frame["T_W_C"].get<std::vector<double>>();
    if (p.size() != 7) continue;
    trajectory[frame["timestamp_ns"].get<std::int64_t>()] = core::isometryFromTranslationQuaternion(
        Eigen::Vector3d(p[0], p[1], p[2]), p[3], p[4], p[5], p[6]);
  }
  return trajectory;
}

void addPlaneFigures(const PlaneEvaluation& planes, nlohmann::json& figures) {
  using nlohmann::json;
  figures["plane_recall"] = planes.planes_counted > 0 ? json(planes.recall) : json(nullptr);
  figures["plane_precision"] = planes.patches > 0 ? json(planes.precision) : json(nullptr);
  figures["planes_counted"] = planes.planes_counted;
  figures["planes_found"] = planes.planes_found;
  figures["patches_evaluated"] = planes.patches;
  figures["patches_matched"] = planes.patches_matched;
  figures["duplicate_patches"] = planes.duplicate_patches;
  double worst_normal = 0.0, worst_offset = 0.0, worst_iou = 1.0;
  json per_plane = json::array();
  for (const PlaneResult& p : planes.planes) {
    if (p.found) {
      worst_normal = std::max(worst_normal, p.normal_error_deg);
      worst_offset = std::max(worst_offset, p.offset_error_m);
      worst_iou = std::min(worst_iou, p.iou);
    }
    per_plane.push_back({{"id", p.id},
                         {"seen_m2", p.seen_m2},
                         {"counted", p.counted},
                         {"found", p.found},
                         {"patch", p.patch_id >= 0 ? json(p.patch_id) : json(nullptr)},
                         {"iou", p.iou},
                         {"normal_error_deg", p.normal_error_deg},
                         {"offset_error_m", p.offset_error_m},
                         {"duplicates", p.duplicates}});
  }
  const bool any = planes.planes_found > 0;
  figures["plane_normal_error_deg_max"] = any ? json(worst_normal) : json(nullptr);
  figures["plane_offset_error_m_max"] = any ? json(worst_offset) : json(nullptr);
  figures["plane_iou_min"] = any ? json(worst_iou) : json(nullptr);
  figures["planes"] = per_plane;
}

// The run's pixels_after (report.json's bytes_after / 3), when it has one.
std::optional<double> pixelsAfter(const nlohmann::json& report) {
  const auto bytes = report.find("bytes_after");
  if (bytes == report.end() || !bytes->is_number()) return std::nullopt;
  return bytes->get<double>() / 3.0;
}

// `report`: the run's report.json, for the economy's pixels_after.
void addTextureFigures(const TextureEvaluation& textures, const nlohmann::json& report,
                       nlohmann::json& figures) {
  using nlohmann::json;
  auto optional = [](const auto& v) { return v ? json(*v) : json(nullptr); };
  figures["gt_psnr_mean"] = optional(textures.psnr_mean_db);
  figures["gt_psnr_min"] = optional(textures.psnr_min_db);
  figures["gt_psnr_registered_mean"] = optional(textures.registered_psnr_mean_db);
  figures["gt_psnr_texels"] = textures.texels;
  figures["gt_psnr_tsdf_baseline_mean"] = optional(textures.baseline_psnr_mean_db);
  // Matching and economy (docs/METRICS.md).
  figures["false_match_rate"] = optional(textures.false_match_rate);
  figures["missed_match_rate"] = optional(textures.missed_match_rate);
  figures["false_matches"] = textures.false_matches;
  figures["missed_matches"] = textures.missed_matches;
  figures["reuses_evaluated"] = textures.reuses;
  figures["stored_evaluated"] = textures.stored;
  // Patterns (docs/METRICS.md, period error): instances on periodic true textures.
  figures["patterns_evaluated"] = textures.patterns;
  figures["patterns_exact"] = textures.patterns_exact;
  figures["ideal_pixels"] = optional(textures.ideal_pixels);
  const std::optional<double> pixels_after = pixelsAfter(report);
  figures["economy"] = textures.ideal_pixels && pixels_after && *pixels_after > 0.0
                           ? json(*textures.ideal_pixels / *pixels_after)
                           : json(nullptr);
  json per_patch = json::array();
  for (const PatchTextureResult& p : textures.patches) {
    per_patch.push_back(
        {{"patch", p.patch_id},
         {"plane", p.plane},
         {"texels", p.texels},
         {"psnr_db", p.psnr_db},
         {"registered_psnr_db", p.registered_psnr_db},
         {"shift_m", p.shift_m},
         {"tsdf_baseline_psnr_db", optional(p.baseline_psnr_db)},
         {"observed_texels", p.observed_texels},
         {"true_texture", p.true_texture},
         {"texture_id", optional(p.texture_id)},
         {"reused", p.reused},
         {"pattern_exact", p.pattern_exact ? json(*p.pattern_exact) : json(nullptr)},
         {"reuse_psnr_db", optional(p.reuse_psnr_db)},
         {"reuse_registered_psnr_db", optional(p.reuse_registered_psnr_db)},
         {"reuse_shift_texels", optional(p.reuse_shift_texels)},
         {"reuse_texels", p.reuse_texels},
         {"false_match", p.false_match},
         {"missed_match", p.missed_match}});
  }
  figures["textures"] = per_patch;
}

// The TSDF mesh of the run, for the baseline PSNR; nothing (with a warning) when unreadable.
std::unique_ptr<fusion::MeshColourSampler> meshBaseline(const std::filesystem::path& run_dir) {
  try {
    return std::make_unique<fusion::MeshColourSampler>(fusion::readPly(run_dir / "mesh.ply"));
  } catch (const core::Error& e) {
    spdlog::warn("no TSDF baseline for the texture PSNR: {}", e.what());
    return nullptr;
  }
}

}  // namespace

nlohmann::json evaluateRun(const std::filesystem::path& run_dir,
                           const std::filesystem::path& ground_truth,
                           const PlaneEvaluationOptions& plane_options) {
  const auto report_path = run_dir / "report.json";
  nlohmann::json report = readJson(report_path);
  const nlohmann::json gt = readJson(ground_truth);

  nlohmann::json figures = {{"ate_m", nullptr}, {"ate_max_m", nullptr}, {"ate_pairs", 0}};
  const auto trajectory_path = run_dir / "trajectory.txt";
  const core::Trajectory truth_poses = groundTruthTrajectory(gt);
  core::Isometry T_gt_est = core::Isometry::Identity();
  if (std::filesystem::exists(trajectory_path)) {
    const core::Trajectory estimate = core::readTumTrajectory(trajectory_path);
    if (const auto ate = core::absoluteTrajectoryError(estimate, truth_poses)) {
      T_gt_est = ate->T_gt_est;
      figures["ate_m"] = ate->rmse_m;
      figures["ate_max_m"] = ate->max_m;
      figures["ate_pairs"] = ate->pairs;
      core::Trajectory aligned;
      for (const auto& [t, pose] : estimate) aligned[t] = ate->T_gt_est * pose;
      core::writeTumTrajectory(aligned, run_dir / "trajectory_aligned.txt");
    }
  }
  // Loop closure's corrected poses, when the run closed loops. The patch map ends in their
  // frame: its planes are compared with the truth through their alignment.
  figures["ate_after_closure_m"] = nullptr;
  const auto closed_path = run_dir / "trajectory_closed.txt";
  if (std::filesystem::exists(closed_path)) {
    if (const auto ate =
            core::absoluteTrajectoryError(core::readTumTrajectory(closed_path), truth_poses)) {
      figures["ate_after_closure_m"] = ate->rmse_m;
      T_gt_est = ate->T_gt_est;
    }
  }
  figures["plane_recall"] = nullptr;
  figures["plane_precision"] = nullptr;
  figures["duplicate_patches"] = nullptr;
  const auto patches_path = run_dir / "patches.json";
  if (gt.contains("planes") && std::filesystem::exists(patches_path)) {
    PlaneEvaluation planes;
    try {
      planes = evaluatePlanes(gt, truth_poses, readJson(patches_path), T_gt_est, plane_options);
    } catch (const core::Error& e) {
      throw core::Error(
          fmt::format("{} against {}: {}", patches_path.string(), ground_truth.string(), e.what()));
    }
    addPlaneFigures(planes, figures);
    figures["plane_max_offset_m"] = plane_options.max_offset_m;
    figures["plane_max_normal_deg"] = plane_options.max_normal_deg;
  }
  figures["gt_psnr_mean"] = nullptr;
  // Null unless the texture figures below can be computed (docs/METRICS.md).
  for (const char* key : {"false_match_rate", "missed_match_rate", "economy"}) {
    figures[key] = nullptr;
  }
  if (gt.contains("planes") && gt.contains("textures") && std::filesystem::exists(patches_path)) {
    const auto baseline = meshBaseline(run_dir);
    try {
      addTextureFigures(evaluateTextures(gt, ground_truth.parent_path(), truth_poses,
                                         readJson(patches_path), run_dir, T_gt_est, baseline.get()),
                        report, figures);
    } catch (const core::Error& e) {
      throw core::Error(
          fmt::format("{} against {}: {}", patches_path.string(), ground_truth.string(), e.what()));
    }
  }
  figures["ground_truth"] = ground_truth.string();
  mergeIntoReport(report_path, report, figures);
  return figures;
}

nlohmann::json evaluateRunViews(const std::filesystem::path& run_dir, core::FrameSource& frames,
                                ViewEvaluationOptions options) {
  const auto report_path = run_dir / "report.json";
  nlohmann::json report = readJson(report_path);
  if (const auto every = report.find("holdout_every");
      every != report.end() && every->is_number_integer()) {
    options.holdout_every = every->get<int>();
  }
  const RenderMesh patches = readTexturedMap(run_dir / options.map_file);
  const RenderMesh mesh = readColouredPly(run_dir / "mesh.ply");
  const core::Trajectory poses = core::readTumTrajectory(run_dir / "trajectory.txt");
  // After a loop closure the patch map lies in the frame of the corrected poses; so does the
  // TSDF mesh when it was fused again at them (report: tsdf_corrected), else it stays in the
  // tracked one.
  const auto closed_path = run_dir / "trajectory_closed.txt";
  const std::optional<core::Trajectory> closed =
      std::filesystem::exists(closed_path) ? std::optional(core::readTumTrajectory(closed_path))
                                           : std::nullopt;
  const auto corrected = report.find("tsdf_corrected");
  const bool mesh_corrected =
      corrected != report.end() && corrected->is_boolean() && corrected->get<bool>();
  std::vector<ViewModel> models = {{"patches", &patches, closed ? &*closed : nullptr},
                                   {"mesh", &mesh, closed && mesh_corrected ? &*closed : nullptr}};
  // The unmatched run's map at its own poses (the same as this run's, from the same input).
  std::optional<RenderMesh> unmatched;
  std::optional<core::Trajectory> unmatched_poses;
  if (!options.unmatched_run.empty()) {
    const std::filesystem::path& other = options.unmatched_run;
    unmatched = readTexturedMap(other / options.map_file);
    const auto other_closed = other / "trajectory_closed.txt";
    unmatched_poses = core::readTumTrajectory(
        std::filesystem::exists(other_closed) ? other_closed : other / "trajectory.txt");
    models.push_back({"unmatched", &*unmatched, &*unmatched_poses});
  }
  const ViewEvaluation views = evaluateViews(models, frames, poses, options);
  if (views.views.empty()) {
    throw core::Error(fmt::format(
        "{}: no view could be scored: none of its frames has a pose in {} with patches in "
        "view (is it the source this run read?)",
        frames.name(), (run_dir / "trajectory.txt").string()));
  }
  nlohmann::json figures = viewFigures(views);
  if (unmatched) {
    const auto patches_path = run_dir / "patches.json";
    figures.update(reuseCostFigures(
        views, 2,
        std::filesystem::exists(patches_path) ? readJson(patches_path) : nlohmann::json::object()));
    figures["view_unmatched_run"] = options.unmatched_run.string();
  }
  figures["view_frames_source"] = frames.name();
  figures["view_map"] = options.map_file.string();
  mergeIntoReport(report_path, report, figures);
  return figures;
}

}  // namespace tessera::eval
