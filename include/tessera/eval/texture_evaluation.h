#pragma once
// Ground-truth PSNR of the patch bitmaps (docs/METRICS.md): each observed texel of a run's
// bitmap against the true texture of the synthetic scene, averaged over the texel's area.
#include <cstddef>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "tessera/core/pose.h"
#include "tessera/eval/trajectory.h"

namespace tessera::fusion {
class MeshColourSampler;
}

namespace tessera::eval {

struct TextureEvaluationOptions {
  double max_plane_distance_m = 0.03;     // a texel lies on a true plane at most this far away
  int supersample = 3;                    // true colour: mean of supersample^2 points per texel
  double baseline_max_distance_m = 0.04;  // mesh vertices farther than this give no colour
  double max_shift_m = 0.03;              // registered PSNR: the largest in-plane shift looked for
};

struct PatchTextureResult {
  int patch_id = 0;
  std::string plane;       // the true plane most of its texels lie on
  std::size_t texels = 0;  // observed texels compared
  double psnr_db = 0.0;    // as placed in the map
  // After shifting the truth in the plane onto the bitmap (phase correlation, at most
  // max_shift_m): the texture's own fidelity, without the patch's placement error.
  double registered_psnr_db = 0.0;
  double shift_m = 0.0;
  std::optional<double> baseline_psnr_db;  // the same texels coloured from the TSDF mesh
};

struct TextureEvaluation {
  std::vector<PatchTextureResult> patches;
  std::size_t texels = 0;
  std::optional<double> psnr_mean_db, psnr_min_db;  // over patches
  std::optional<double> registered_psnr_mean_db;
  std::optional<double> baseline_psnr_mean_db;
};

// `truth`: a parsed .gt.json with planes and textures (image paths in their definitions are
// resolved against its scene_dir, else truth_dir); `truth_poses` its camera poses (their mean
// position says which side of a plane the room is); `patches`: a parsed patches.json whose texture
// images are under run_dir; T_gt_est maps the run's world frame onto the truth's. `baseline`, when
// given, colours the same texels from the TSDF mesh. Texels whose area spans two true surfaces, or
// none, are left out. Throws core::Error naming what is missing (a ground truth written before it
// held texture definitions, an unreadable image).
TextureEvaluation evaluateTextures(const nlohmann::json& truth,
                                   const std::filesystem::path& truth_dir,
                                   const Trajectory& truth_poses, const nlohmann::json& patches,
                                   const std::filesystem::path& run_dir,
                                   const core::Isometry& T_gt_est,
                                   const fusion::MeshColourSampler* baseline,
                                   const TextureEvaluationOptions& options = {});

}  // namespace tessera::eval
