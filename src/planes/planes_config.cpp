#include "tessera/planes/planes_config.h"

#include "tessera/core/error.h"

namespace tessera::planes {

void readConfig(const core::ConfigSection& section, PlaneDetectorConfig& config) {
  section.read("working_scale", config.working_scale);
  section.read("block_size", config.block_size);
  section.read("baseline_m", config.baseline_m);
  section.read("threshold_px", config.threshold_px);
  section.read("refit_threshold_px", config.refit_threshold_px);
  section.read("strip_width_px", config.strip_width_px);
  section.read("min_pixels", config.min_pixels);
  section.read("min_depth_m", config.min_depth_m);
  section.read("max_depth_m", config.max_depth_m);
  if (config.working_scale < 1 || config.working_scale > 8) {
    throw core::ConfigError("planes: working_scale must be between 1 and 8");
  }
  if (config.block_size < 4 || config.min_pixels < 3 || config.strip_width_px < 0) {
    throw core::ConfigError(
        "planes: block_size must be at least 4, min_pixels at least 3, strip_width_px at least 0");
  }
  if (config.baseline_m <= 0.0 || config.threshold_px <= 0.0 || config.refit_threshold_px <= 0.0) {
    throw core::ConfigError(
        "planes: baseline_m, threshold_px and refit_threshold_px must be positive");
  }
  if (config.min_depth_m < 0.0 || config.max_depth_m <= config.min_depth_m) {
    throw core::ConfigError("planes: need 0 <= min_depth_m < max_depth_m");
  }
}

void readConfig(const core::ConfigSection& section, PatchMapConfig& config) {
  section.read("max_normal_angle_deg", config.max_normal_angle_deg);
  section.read("colour_neighbour_angle_deg", config.colour_neighbour_angle_deg);
  section.read("colour_neighbour_offset_m", config.colour_neighbour_offset_m);
  section.read("max_offset_m", config.max_offset_m);
  section.read("merge_bend_deg", config.merge_bend_deg);
  section.read("move_within_plane", config.move_within_plane);
  section.read("min_move_within_plane_m", config.min_move_within_plane_m);
  section.read("moved_settle_frames", config.moved_settle_frames);
  section.read("max_tiles_moved_per_frame", config.max_tiles_moved_per_frame);
  section.read("cell_m", config.cell_m);
  section.read("stable_frames", config.stable_frames);
  section.read("max_growth", config.max_growth);
  section.read("out_of_view_frames", config.out_of_view_frames);
  section.read("min_area_m2", config.min_area_m2);
  section.read("release_samples_after_frames", config.release_samples_after_frames);
  section.read("tile_m", config.tile_m);
  section.read("sample_cell_m", config.sample_cell_m);
  section.read("sample_views", config.sample_views);
  section.read("colour_every_n_frames", config.colour_every_n_frames);
  section.read("colour_at_colour_time", config.colour_at_colour_time);
  section.read("colour_depth_tolerance_m", config.colour_depth_tolerance_m);
  section.read("colour_depth_tolerance_per_m2", config.colour_depth_tolerance_per_m2);
  section.read("colour_edge_margin_px", config.colour_edge_margin_px);
  section.read("exposure_compensation", config.exposure_compensation);
  if (config.max_normal_angle_deg <= 0.0 || config.max_offset_m <= 0.0 || config.cell_m <= 0.0) {
    throw core::ConfigError(
        "patches: max_normal_angle_deg, max_offset_m and cell_m must be positive");
  }
  if (config.moved_settle_frames < 0 || config.max_tiles_moved_per_frame < 0) {
    throw core::ConfigError(
        "patches: moved_settle_frames and max_tiles_moved_per_frame must be at least 0");
  }
  if (config.min_move_within_plane_m <= 0.0) {
    throw core::ConfigError("patches: min_move_within_plane_m must be positive");
  }
  if (config.merge_bend_deg < 0.0 || config.merge_bend_deg >= 90.0) {
    throw core::ConfigError("patches: merge_bend_deg must be in [0, 90)");
  }
  if (config.tile_m < 0.0) {
    throw core::ConfigError("patches: tile_m must be 0 (never cut planes) or positive");
  }
  if (config.release_samples_after_frames < 0) {
    throw core::ConfigError("patches: release_samples_after_frames must be 0 (keep) or positive");
  }
  if (config.colour_neighbour_angle_deg < 0.0 || config.colour_neighbour_angle_deg >= 90.0 ||
      config.colour_neighbour_offset_m < 0.0) {
    throw core::ConfigError(
        "patches: colour_neighbour_angle_deg must be 0 to under 90, colour_neighbour_offset_m "
        "at least 0");
  }
  if (config.stable_frames < 1 || config.out_of_view_frames < 1 || config.max_growth < 0.0) {
    throw core::ConfigError(
        "patches: stable_frames and out_of_view_frames must be at least 1, max_growth at least 0");
  }
  if (config.min_area_m2 < 0.0 || config.sample_cell_m <= 0.0 || config.colour_every_n_frames < 1 ||
      config.colour_depth_tolerance_m <= 0.0 || config.colour_depth_tolerance_per_m2 < 0.0 ||
      config.colour_edge_margin_px < 0 || config.sample_views < 0 || config.sample_views > 16) {
    throw core::ConfigError(
        "patches: min_area_m2, colour_depth_tolerance_per_m2 and colour_edge_margin_px must be "
        "at least 0, sample_views 0 to 16, sample_cell_m and colour_depth_tolerance_m positive, "
        "colour_every_n_frames "
        "at least 1");
  }
}

void readConfig(const core::ConfigSection& section, PlaneAlignmentConfig& config) {
  section.read("enabled", config.enabled);
  section.read("min_patch_area_m2", config.min_patch_area_m2);
  section.read("min_patch_frames", config.min_patch_frames);
  section.read("points_per_region", config.points_per_region);
  section.read("max_step_m", config.max_step_m);
  section.read("max_step_deg", config.max_step_deg);
  if (config.min_patch_area_m2 < 0.0 || config.min_patch_frames < 0 ||
      config.points_per_region < 3 || config.max_step_m <= 0.0 || config.max_step_deg <= 0.0) {
    throw core::ConfigError(
        "pose_correction: min_patch_area_m2 and min_patch_frames must be at least 0, "
        "points_per_region at least 3, max_step_m and max_step_deg positive");
  }
}

}  // namespace tessera::planes
