#pragma once
// Ground-truth PSNR of the patch bitmaps (docs/METRICS.md): each observed texel of a run's
// bitmap against the true texture of the synthetic scene, averaged over the texel's area; and
// the ground-truth matching figures: false and missed matches, the ideal texture size.
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "tessera/core/pose.h"
#include "tessera/core/trajectory.h"

namespace tessera::fusion {
class MeshColourSampler;
}

namespace tessera::eval {

struct TextureEvaluationOptions {
  double max_plane_distance_m = 0.03;     // a texel lies on a true plane at most this far away
  int supersample = 3;                    // true colour: mean of supersample^2 points per texel
  double baseline_max_distance_m = 0.04;  // mesh vertices farther than this give no colour
  double max_shift_m = 0.03;              // registered PSNR: the largest in-plane shift looked for
  // A reuse is a false match (docs/METRICS.md "Matching") when the reused texture, rendered
  // through the instance's transform onto the patch's grid, lies more than this many texels off
  // the truth once the patch's own placement error (its bitmap's registration shift) is taken
  // out...
  double max_reuse_shift_texels = 2.0;
  // ...or when its registered PSNR against the truth is more than this many dB below that of the
  // patch's own bitmap (it shows another texture).
  double max_reuse_psnr_drop_db = 6.0;
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
  std::size_t observed_texels = 0;         // observed texels of the bitmap (state 255)

  // Matching (patches.json "instance": the database texture the map shows for the patch).
  std::string true_texture;                // the texture of `plane` in the ground truth
  std::optional<std::int64_t> texture_id;  // the instance's texture; nothing without instance
  bool reused = false;                     // the texture existed before this patch
  // A reuse: its texture rendered through the instance's transform onto the bitmap's grid,
  // against the truth over the texels both have (as placed, and registered as above), and
  // |its registration shift - the bitmap's| in texels. Nothing when the render covers none of
  // those texels (the map shows nothing of the surface there: a false match).
  std::optional<double> reuse_psnr_db, reuse_registered_psnr_db, reuse_shift_texels;
  std::size_t reuse_texels = 0;  // texels compared
  bool false_match = false;      // a reuse off by more than the options' bounds
  bool missed_match = false;     // stored its own though its true texture was stored before
  // A pattern instance on a periodic true texture: whether its lattice is the true one within
  // 1 texel (METRICS.md, period error).
  std::optional<bool> pattern_exact;
};

struct TextureEvaluation {
  std::vector<PatchTextureResult> patches;
  std::size_t texels = 0;
  std::optional<double> psnr_mean_db, psnr_min_db;  // over patches
  std::optional<double> registered_psnr_mean_db;
  std::optional<double> baseline_psnr_mean_db;

  // Over the evaluated patches (docs/METRICS.md "Matching"): reuses judged, false among them;
  // patches that stored their own texture, missed among them.
  std::size_t reuses = 0, false_matches = 0, stored = 0, missed_matches = 0;
  // Pattern instances on periodic true textures, and those with the exact lattice.
  std::size_t patterns = 0, patterns_exact = 0;
  std::optional<double> false_match_rate;   // false_matches / reuses
  std::optional<double> missed_match_rate;  // missed / (missed + reuses that are not false)
  // Each distinct true texture of the patches once: its period cell when periodic, else the
  // most observed texels of one patch on it, in texels of mean_texel_m (docs/METRICS.md
  // "Texture economy"); economy = ideal_pixels / the run's pixels_after.
  std::optional<double> ideal_pixels;
  std::optional<double> mean_texel_m;  // over the run's bitmaps
};

// `truth`: a parsed .gt.json with planes and textures (image paths in their definitions are
// resolved against its scene_dir, else truth_dir); `truth_poses` its camera poses (their mean
// position says which side of a plane the room is); `patches`: a parsed patches.json whose texture
// images are under run_dir; T_gt_est maps the run's world frame onto the truth's. `baseline`, when
// given, colours the same texels from the TSDF mesh. Texels whose area spans two true surfaces, or
// none, are left out. A patch whose "instance" is a reuse also has the reused texture rendered
// onto its grid and compared with the same truth; a patch that stored its own texture is a
// missed match when an earlier-stored texture of the run (a lower texture id, stored by a patch)
// came from the same true texture. Throws core::Error naming what is missing (a ground truth
// written before it held texture definitions, an unreadable image).
TextureEvaluation evaluateTextures(
    const nlohmann::json& truth, const std::filesystem::path& truth_dir,
    const core::Trajectory& truth_poses, const nlohmann::json& patches,
    const std::filesystem::path& run_dir, const core::Isometry& T_gt_est,
    const fusion::MeshColourSampler* baseline, const TextureEvaluationOptions& options = {});

}  // namespace tessera::eval
