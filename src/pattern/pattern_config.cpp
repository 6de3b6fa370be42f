#include "tessera/pattern/pattern_config.h"

#include "tessera/core/error.h"

namespace tessera::pattern {

void readConfig(const core::ConfigSection& section, PatternStageConfig& config) {
  PatternConfig& p = config.extractor;
  section.read("enabled", config.enabled);
  section.read("analysis_max_px", p.analysis_max_px);
  section.read("min_peak", p.lattice.min_peak);
  section.read("peak_drop", p.lattice.peak_drop);
  section.read("blur_sigma_px", p.blur_sigma_px);
  section.read("min_period_px", p.lattice.min_period_px);
  section.read("stripe_rho", p.lattice.stripe_rho);
  section.read("min_angle_deg", p.lattice.min_angle_deg);
  if (section.has("min_psnr_db")) {  // the name it had when two sections used it
    throw core::ConfigError(
        "pattern: min_psnr_db is now min_tiling_psnr_db (the tiling's own PSNR; "
        "match.min_psnr_db is the rule for a reuse)");
  }
  section.read("min_tiling_psnr_db", p.min_tiling_psnr_db);
  section.read("min_explained", p.min_explained);
  section.read("max_overlay_share", p.max_overlay_share);
  section.read("min_repeats", p.min_repeats);
  section.read("finer_psnr_loss_db", p.finer_psnr_loss_db);
  section.read("repeat_error_ratio", p.lattice.repeat_error_ratio);
  section.read("overlay_sigmas", p.overlay_sigmas);
  section.read("min_overlay_error", p.min_overlay_error);
  section.read("min_overlay_px", p.min_overlay_px);
  section.read("max_tile_repetitions", p.max_tile_repetitions);
  section.read("shading", p.shading);
  section.read("shading_cells", p.shading_cells);
  section.read("min_shading_spread", p.min_shading_spread);
  section.read("min_overlay_side_px", config.min_overlay_side_px);
  section.read("min_overlay_area_px", config.min_overlay_area_px);
  section.read("overlay_margin_px", config.overlay_margin_px);
  if (config.min_overlay_side_px < 1 || config.min_overlay_area_px < 1 ||
      config.overlay_margin_px < 0) {
    throw core::ConfigError(
        "pattern: min_overlay_side_px and min_overlay_area_px must be >= 1, overlay_margin_px "
        ">= 0");
  }
  if (p.shading_cells < 0.5 || p.min_shading_spread < 0.0) {
    throw core::ConfigError("pattern: shading_cells must be >= 0.5, min_shading_spread >= 0");
  }
  if (p.analysis_max_px < 16) throw core::ConfigError("pattern: analysis_max_px must be >= 16");
  if (p.max_tile_repetitions < 0 || (p.max_tile_repetitions > 0 && p.max_tile_repetitions < 3)) {
    throw core::ConfigError("pattern: max_tile_repetitions must be 0 (all) or >= 3");
  }
  if (p.lattice.min_peak <= 0.0 || p.lattice.min_peak >= 1.0 || p.lattice.peak_drop < 0.0 ||
      p.blur_sigma_px < 0.0 || p.lattice.stripe_rho <= 0.0 || p.lattice.stripe_rho > 1.0) {
    throw core::ConfigError(
        "pattern: min_peak must be in (0, 1), peak_drop and blur_sigma_px >= 0, stripe_rho in (0, "
        "1]");
  }
  if (p.lattice.min_period_px < 1.0 || p.lattice.min_angle_deg <= 0.0 ||
      p.lattice.min_angle_deg > 60.0) {
    throw core::ConfigError("pattern: min_period_px must be >= 1, min_angle_deg in (0, 60]");
  }
  if (p.min_explained < 0.0 || p.min_explained > 1.0 || p.max_overlay_share < 0.0 ||
      p.max_overlay_share >= 1.0 || p.min_repeats < 2.0 || p.min_overlay_px < 1 ||
      p.finer_psnr_loss_db < 0.0 || p.lattice.repeat_error_ratio < 1.0) {
    throw core::ConfigError(
        "pattern: min_explained must be in [0, 1], max_overlay_share in [0, 1), min_repeats "
        ">= 2, min_overlay_px >= 1, finer_psnr_loss_db >= 0, repeat_error_ratio >= 1");
  }
}

}  // namespace tessera::pattern
