#pragma once
// View PSNR, SSIM and detail (docs/METRICS.md, image_similarity.h): a run's textured patches
// rendered from the run's own camera poses into the captured colour frames, compared over the
// pixels the patches cover, beside
// other models (the run's vertex-coloured TSDF mesh; in bench/, Open3D's meshes) rendered the
// same way and compared over exactly the same pixels.
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "tessera/core/frame_source.h"
#include "tessera/core/trajectory.h"
#include "tessera/eval/image_similarity.h"
#include "tessera/eval/view_render.h"

namespace tessera::eval {

struct ViewModel {
  std::string name;
  const RenderMesh* mesh = nullptr;
  // The poses of the frame the mesh lies in, when not the shared ones (after a loop closure
  // the patch map lies in the corrected frame, the TSDF mesh in the tracked one).
  const core::Trajectory* poses = nullptr;
};

struct ViewEvaluationOptions {
  int max_views = 20;     // training views, spread evenly over the frames; held-out views likewise
  int holdout_every = 0;  // the run's --holdout-every
  // A rendered patch pixel counts only where the captured depth agrees with the patch's depth
  // within depth_tolerance_m + depth_tolerance_per_m2 * z^2 (the structured-light noise grows
  // with z^2): where something stands in front of the patch, the patch is not what was seen.
  double depth_tolerance_m = 0.02;
  double depth_tolerance_per_m2 = 0.005;
  // Pixels within this many pixels of one that fails the depth test are not compared either:
  // at a depth discontinuity a real sensor's colour and depth disagree by a few pixels, so the
  // captured colour there may belong to the other surface (tessera eval --edge-margin).
  int edge_margin_px = 2;
  std::size_t min_pixels = 500;    // views with fewer common pixels are not scored
  std::filesystem::path save_dir;  // non-empty: render | captured | difference PNGs
  // The map rendered as "patches", relative to the run folder: patches.obj, map.obj or
  // map.glb (tessera eval --map).
  std::filesystem::path map_file = "patches.obj";
  int save_views = 4;
  // Render each view at the pose of the time its colour image was taken, interpolated from the
  // poses around it, where the source gives colour time stamps: the colour was captured there,
  // not at the depth image's time (tessera eval --pose-time). Else, and for sources without
  // colour stamps, at the depth image's time.
  bool colour_time = true;
  // The same run made without matching (tessera eval --unmatched): its map is rendered too, over
  // the same pixels, for what the reuses cost the view (reuse_cost.h). Empty: none.
  std::filesystem::path unmatched_run;
};

struct ViewScore {
  std::uint64_t index = 0;
  std::int64_t timestamp_ns = 0;
  bool held_out = false;
  std::size_t pixels = 0;                   // compared, the same for every model
  bool at_colour_time = false;  // rendered at the colour image's time (else the depth's)
  std::vector<ImageSimilarity> similarity;  // per model
};

// One surface of the first model (RenderMesh::surfaces: a patch's object) over the training
// views: the compared pixels it covered and each model's summed squared error there.
struct SurfaceError {
  std::string name;
  std::size_t pixels = 0;
  std::vector<double> squared_error;  // per model, over R, G and B
  // PSNR of `model` over this surface's pixels; nullopt without pixels.
  std::optional<double> psnr(std::size_t model) const;
};

struct ViewEvaluation {
  std::vector<std::string> models;
  std::vector<ViewScore> views;
  std::vector<SurfaceError> surfaces;  // per surface of models[0]'s mesh
  // Mean over the scored views (training or held-out) of one of model m's figures; nothing
  // without views.
  std::optional<double> mean(std::size_t model, bool held_out,
                             double ImageSimilarity::*figure) const;
  std::optional<double> meanPsnr(std::size_t model, bool held_out) const {
    return mean(model, held_out, &ImageSimilarity::psnr_db);
  }
  std::size_t pixels(bool held_out) const;
  std::size_t viewCount(bool held_out) const;
  // "colour" or "depth": the time every scored view was rendered at; "mixed" when both.
  std::string poseTime() const;
};

// Renders every model at each chosen frame's pose in `poses` (by timestamp, within 1 ms) and
// compares it with the frame's colour over the common pixels: covered by models[0], its depth
// confirmed by the captured depth, and covered by every other model. Frames without a pose
// are skipped. `progress`, when given, is called after each view scored. Throws core::Error
// when no model is given or the source fails.
ViewEvaluation evaluateViews(const std::vector<ViewModel>& models, core::FrameSource& frames,
                             const core::Trajectory& poses, const ViewEvaluationOptions& options);

// The report.json keys of docs/METRICS.md for a run evaluated as {patches, mesh}: for each
// figure F of psnr, ssim and detail, view_F_mean, view_F_baseline_mean, view_F_holdout_mean
// and view_F_baseline_holdout_mean; view_detail_correlation_mean and
// view_detail_energy_ratio_mean with their baseline_ variants; view_pixels,
// view_pixels_holdout, view_frames, view_frames_holdout (null where there are no views);
// view_pose_time; view_surfaces_worst, the surfaces that lose most against the baseline.
nlohmann::json viewFigures(const ViewEvaluation& evaluation);

}  // namespace tessera::eval
