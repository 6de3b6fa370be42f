#include "tessera/loop/loop_config.h"

#include "tessera/core/error.h"

namespace tessera::loop {

void readConfig(const core::ConfigSection& section, LoopConfig& config) {
  section.read("enabled", config.enabled);
  section.read("hold_apart_unjoined_segments", config.hold_apart_unjoined_segments);
  section.read("min_travel_m", config.min_travel_m);
  section.read("max_descriptor_distance", config.max_descriptor_distance);
  section.read("neighbours_per_descriptor", config.neighbours_per_descriptor);
  section.read("min_votes", config.min_votes);
  section.read("candidates_per_query", config.candidates_per_query);
  section.read("query_descriptors", config.query_descriptors);
  section.read("query_every_n_keyframes", config.query_every_n_keyframes);
  section.read("max_view_distance_m", config.max_view_distance_m);
  section.read("max_drift_fraction", config.max_drift_fraction);
  section.read("max_drift_m", config.max_drift_m);
  section.read("max_drift_deg", config.max_drift_deg);
  section.read("max_drift_deg_per_m", config.max_drift_deg_per_m);
  section.read("confirm_within_keyframes", config.confirm_within_keyframes);
  section.read("consistency_m", config.consistency_m);
  section.read("consistency_deg", config.consistency_deg);
  section.read("dense_stride", config.dense_stride);
  section.read("dense_max_depth_m", config.dense_max_depth_m);
  section.read("icp_distance_m", config.icp_distance_m);
  section.read("min_fitness", config.min_fitness);
  section.read("max_icp_rmse_m", config.max_icp_rmse_m);
  section.read("edge_prune_threshold", config.edge_prune_threshold);
  section.read("reoptimise_m", config.reoptimise_m);
  section.read("node_spacing_m", config.node_spacing_m);
  section.read("node_spacing_deg", config.node_spacing_deg);
  section.read("cover_radius_m", config.cover_radius_m);
  section.read("cover_angle_deg", config.cover_angle_deg);
  if (config.min_travel_m < 0.0 || config.max_descriptor_distance < 0 ||
      config.neighbours_per_descriptor < 1 || config.min_votes < 1 ||
      config.candidates_per_query < 1 || config.query_descriptors < 1 ||
      config.query_every_n_keyframes < 1 || config.confirm_within_keyframes < 0 ||
      config.dense_stride < 1 || config.icp_distance_m <= 0.0 || config.dense_max_depth_m <= 0.0 || config.min_fitness < 0.0 ||
      config.min_fitness > 1.0 || config.edge_prune_threshold < 0.0 ||
      config.edge_prune_threshold > 1.0 || config.node_spacing_m < 0.0 ||
      config.node_spacing_deg < 0.0) {
    throw core::ConfigError(
        "loop_closure: distances and counts must be positive (min_votes, candidates, "
        "neighbours, dense_stride at least 1), min_fitness and edge_prune_threshold in [0, 1]");
  }
}

}  // namespace tessera::loop
