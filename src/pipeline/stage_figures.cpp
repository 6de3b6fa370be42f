#include "tessera/pipeline/stage_figures.h"

#include <algorithm>
#include <cmath>
#include <numeric>

#include "internal/json_values.h"

namespace tessera::pipeline {

using nlohmann::json;

using internal::orNull;
using internal::ratio;

std::optional<double> percentile(std::vector<double> values, double p) {
  if (values.empty()) return std::nullopt;
  const auto rank = static_cast<std::size_t>(std::ceil(p * static_cast<double>(values.size())));
  const std::size_t k = std::clamp<std::size_t>(rank, 1, values.size()) - 1;
  std::nth_element(values.begin(), values.begin() + static_cast<long>(k), values.end());
  return values[k];
}

void FrameFigures::addTo(json& line) const {
  line["tracking_ms"] = tracking_ms;
  line["integration_ms"] = integration_ms;
  line["planes_ms"] = planes_ms;
  line["tsdf_bytes"] = tsdf_bytes;
  line["tsdf_blocks_released"] = tsdf_blocks_released;
  line["colour_sample_bytes"] = colour_sample_bytes;
  line["planes_detected"] = planes_detected;
  line["patches_live"] = patches_live;
  line["patches_finalized"] = patches_finalized;
  if (loop_keyframes_waiting) line["loop_keyframes_waiting"] = *loop_keyframes_waiting;
  if (latency_ms) line["latency_ms"] = *latency_ms;
}

void PatchCommitFigures::addTo(json& line) const {
  line["bitmap_ms"] = bitmap_ms;
  line["describe_ms"] = describe_ms;
  line["match_ms"] = match_ms;
  line["precheck_ms"] = precheck_ms;
  line["pattern_ms"] = pattern_ms;
  line["commit_latency_ms"] = commit_latency_ms;
  line["describe_queued_ms"] = describe_queued_ms;
  line["commit_queued_ms"] = commit_queued_ms;
  line["ccv_considered"] = ccv_considered;
  line["ccv_removed"] = ccv_removed;
}

void SourceFigures::addTo(json& report) const {
  report["live"] = live;
  // Replay never drops; a live device's frames that the busy pipeline never read do.
  report["frames_dropped"] = live_stats.frames_dropped;
  report["frames_bad"] = frames_bad;
  report["stopped_on_request"] = stopped_on_request;
  report["frames_delivered"] = live ? json(live_stats.frames_delivered) : json(nullptr);
  report["drop_rate"] =
      live ? orNull(ratio(live_stats.frames_dropped, live_stats.frames_delivered)) : json(nullptr);
  report["device_losses"] = live_stats.device_losses;
  report["device_reconnects"] = live_stats.reconnects;
  report["source_end_problem"] = end_problem.empty() ? json(nullptr) : json(end_problem);
}

void StreamFigures::addTo(json& report) const {
  report["frames"] = frames;
  report["latency_ms_p50"] = orNull(latency_ms_p50);
  report["latency_ms_p95"] = orNull(latency_ms_p95);
  report["rss_growth_mb_per_1000_frames"] = orNull(rss_growth_mb_per_1000_frames);
}

void CpuFigures::addTo(json& report) const {
  report["cpu_s_stream"] = stream_s;
  report["cpu_ms_per_frame"] =
      frames > 0 ? json(1e3 * stream_s / static_cast<double>(frames)) : json(nullptr);
  report["cpu_cores_stream"] =
      elapsed_stream_s > 0.0 ? json(stream_s / elapsed_stream_s) : json(nullptr);
  report["cpu_s_end_of_stream"] = end_of_stream_s;
  report["cpu_s_finish"] = finish_s;
  report["cpu_s_total"] = stream_s + end_of_stream_s + finish_s;
}

void TrackingFigures::addTo(json& report) const {
  report["poses"] = poses;
  report["tracking_losses"] = tracking_losses;
  report["tracking_restarts"] = tracking_restarts;
  report["relocalisations"] = relocalisations;
  report["feature_poses"] = feature_poses;
  report["keyframes_made"] = keyframes_made;
  report["relocalisation_keyframes"] = relocalisation_keyframes;
  if (continued_map_keyframes > 0) {
    report["continued_map_keyframes"] = continued_map_keyframes;
    report["continued_map_found_at_frame"] =
        continued_map_found_at_frame ? json(*continued_map_found_at_frame) : json(nullptr);
  }
}

void IntegrationFigures::addTo(json& report) const {
  report["holdout_every"] = holdout_every;
  report["frames_integrated"] = frames_integrated;
  report["frames_without_pose"] = frames_without_pose;
  report["frames_held_out"] = frames_held_out;
  report["frames_held_apart"] = frames_held_apart;
  report["frames_between_integrations"] = frames_between_integrations;
  report["frames_shed"] = frames_shed;
  report["tsdf_bytes"] = tsdf_bytes;
  report["tsdf_blocks_released"] = tsdf_blocks_released;
}

void PlaneFigures::addTo(json& report) const {
  report["patches_finalized"] = patches_finalized;
  report["patch_finalizations"] = patch_finalizations;
  report["patch_finalizations_by_reason"] = finalizations_by_reason;
  report["patches_retired"] = patches_retired;
  report["colour_samples"] = colour_samples;
  report["colour_sample_bytes"] = colour_sample_bytes;
  report["samples_released"] = samples_released;
  report["colour_frames_shed"] = colour_frames_shed;
  report["plane_searches_shed"] = plane_searches_shed;
  report["loop_corrections_followed"] = loop_corrections_followed;
  report["loop_planes_moved"] = loop_planes_moved;
  report["loop_planes_merged"] = loop_planes_merged;
  report["loop_tiles_moved_within_planes"] = loop_tiles_moved_within_planes;
  report["loop_follow_ms"] = loop_follow_ms;
  report["loop_follow_frame_ms_max"] = loop_follow_frame_ms_max;
}

void BitmapFigures::addTo(json& report) const {
  report["bitmaps"] = bitmaps;
  report["bitmap_texels_observed"] = texels_observed;
  report["bitmap_texels_inpainted"] = texels_inpainted;
  report["bitmap_bytes"] = bytes;
  report["bitmap_ms_per_m2"] = ms_per_m2;
}

void CommitFigures::addTo(json& report) const {
  report["textures_stored"] = textures_stored;
  report["patterns_stored"] = patterns_stored;
  report["textures_removed"] = textures_removed;
  report["commit_failures"] = commit_failures;
  report["ccv_considered"] = ccv_considered;
  report["ccv_rejection"] = orNull(ratio(ccv_removed, ccv_considered));
  report["commit_latency_ms_p50"] = orNull(commit_latencies_ms.quantile(0.50));
  report["commit_latency_ms_p95"] = orNull(commit_latencies_ms.quantile(0.95));
  report["describe_queued_ms_p50"] = orNull(describe_queued_ms.quantile(0.50));
  report["describe_queued_ms_p95"] = orNull(describe_queued_ms.quantile(0.95));
  report["commit_queued_ms_p50"] = orNull(commit_queued_ms.quantile(0.50));
  report["commit_queued_ms_p95"] = orNull(commit_queued_ms.quantile(0.95));
  report["db_commit_ms_p50"] = orNull(store_commit_ms.quantile(0.50));
  report["db_commit_ms_p95"] = orNull(store_commit_ms.quantile(0.95));
  report["match_ms_p50"] = match.count() > 0 ? json(match.medianMs()) : json(nullptr);
}

void addEconomy(const reuse::Economy& economy, json& report) {
  report["textures_matched"] = economy.textures_matched;
  report["patterns_matched"] = economy.patterns_matched;
  report["overlays"] = economy.overlays;
  report["textured_patches"] = economy.textured_patches;
  report["reuses"] = economy.reuses;
  report["reuse_rate"] = orNull(ratio(economy.reuses, economy.textured_patches));
  report["bytes_before"] = 3 * economy.pixels_before;
  report["bytes_after"] = 3 * economy.pixels_after;
  report["compression"] = orNull(ratio(economy.pixels_before, economy.pixels_after));
  // The fidelity of the patches shown through another image than their own bitmap.
  std::vector<double> psnrs = economy.shown_psnrs_db;
  std::sort(psnrs.begin(), psnrs.end());
  report["patch_psnr_mean"] = psnrs.empty()
                                  ? json(nullptr)
                                  : json(std::accumulate(psnrs.begin(), psnrs.end(), 0.0) /
                                         static_cast<double>(psnrs.size()));
  report["patch_psnr_p5"] = orNull(percentile(psnrs, 0.05));
  report["patch_psnr_min"] = psnrs.empty() ? json(nullptr) : json(psnrs.front());
  report["patch_psnr_own"] = economy.textured_patches - psnrs.size();  // infinite: own bitmap
}

void DatabaseFigures::addTo(json& report) const {
  report["db"] = location;
  report["db_run_id"] = run_id;
  report["db_instances"] = instances;
  if (server_link) {
    const db::ServerLink& link = *server_link;
    report["db_server"] = {{"outages", link.outages},
                           {"disconnected_s", link.disconnected_s},
                           {"queued_commits", link.queued_commits},
                           {"replayed_commits", link.replayed_commits},
                           {"replayed_textures", link.replayed_textures},
                           {"refused_commits", link.refused_commits},
                           {"pending_commits", link.pending_commits},
                           {"removed_at_end", link.removed_at_end},
                           {"journal", link.journal}};
  }
}

void LoopFigures::addTo(json& report) const {
  report["loop_closure"] = enabled;
  report["keyframes"] = loops.keyframes;
  report["loop_closures"] = loops.loop_closures;
  report["loop_closures_rejected"] = loops.rejected();
  report["loop_candidates_checked"] = loops.candidates_checked;
  report["loop_revisits_verified"] = loops.revisits_verified;
  report["loops_rejected_as_drift"] = loops.rejected_as_drift;
  report["loops_rejected_unconfirmed"] = loops.rejected_unconfirmed;
  report["loops_rejected_by_graph"] = loops.rejected_by_graph;
  report["tracking_segments"] = loops.segments;
  report["segments_joined"] = loops.segments_joined;
  report["segments_joined_by_relocalisation"] = loops.relocalisation_joins;
  report["loop_keyframes_covered"] = loops.keyframes_covered;
  report["pose_graph_optimisations"] = loops.optimisations;
  report["pose_graph_ms"] = loops.pose_graph_ms;
  report["loop_keyframe_ms"] = loops.keyframe_ms;
  report["loop_keyframe_cpu_ms"] = loops.keyframe_cpu_ms;
  // ... and its parts (the rest: bookkeeping and waiting for the CPU between them).
  report["loop_information_ms"] = loops.information_ms;
  report["loop_place_lookup_ms"] = loops.place_lookup_ms;
  report["loop_place_index_ms"] = loops.place_index_ms;
  report["loop_verification_ms"] = loops.verification_ms;
  report["loop_patches_retired_in_db"] = instances_retired;
  report["loop_wait_s"] = wait_s;
  report["tsdf_corrected"] = tsdf_corrected;
  report["tsdf_frames_kept"] = tsdf_frames_kept;
  report["tsdf_frames_kept_mb"] = static_cast<double>(tsdf_frames_kept_bytes) / 1e6;
  report["tsdf_correction_s"] = tsdf_correction_s;
  report["ate_after_closure_m"] =
      ate_after_closure ? json(ate_after_closure->rmse_m) : json(nullptr);
  report["ate_after_closure_pairs"] = ate_after_closure ? ate_after_closure->pairs : 0;
  report["poses_apart"] = poses_apart;
}

void ExportFigures::addTo(json& report) const {
  report["mesh_vertices"] = mesh_vertices;
  report["map_triangles"] = map_triangles;
}

}  // namespace tessera::pipeline
