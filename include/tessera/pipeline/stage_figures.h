#pragma once
// The figures of `tessera run`, one small struct per stage. The stage keeps its struct, and the
// struct writes its own keys: a frame's into its stats.jsonl line, a stage's totals into
// report.json (docs/METRICS.md). The monitor and the run's summary hold the same structs.
#include <cstddef>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "tessera/core/frame_source.h"
#include "tessera/core/quantiles.h"
#include "tessera/core/trajectory.h"
#include "tessera/db/texture_store.h"
#include "tessera/loop/loop_graph.h"
#include "tessera/pipeline/stage_timer.h"
#include "tessera/reuse/map_economy.h"

namespace tessera::pipeline {

// The p-quantile (nearest rank) of `values`; nothing when there are none.
std::optional<double> percentile(std::vector<double> values, double p);

// One frame as the stages leave it (TrackedFrame, FusedFrame): its stats.jsonl line and the
// monitor's frame figures.
struct FrameFigures {
  double tracking_ms = 0.0;
  double integration_ms = 0.0;
  double planes_ms = 0.0;
  std::size_t tsdf_bytes = 0;
  std::size_t tsdf_blocks_released = 0;  // this frame, far behind the camera
  std::size_t colour_sample_bytes = 0;   // the patches' colour samples in memory (not spilled)
  std::size_t planes_detected = 0;
  std::size_t patches_live = 0, patches_finalized = 0;
  // With loop closure: keyframes handed over and not yet taken up by its worker.
  std::optional<std::size_t> loop_keyframes_waiting;
  // Live sources: from the frame's arrival at this host to the end of its integration.
  std::optional<double> latency_ms;
  void addTo(nlohmann::json& line) const;
};

// One patch through matching and commit (CommitRecord): its stats.jsonl line and the
// monitor's commit figures.
struct PatchCommitFigures {
  double bitmap_ms = 0.0, describe_ms = 0.0, match_ms = 0.0, pattern_ms = 0.0;
  double precheck_ms = 0.0;        // the cascade ahead of the commit, on a describing thread
  double commit_latency_ms = 0.0;  // finalization to commit
  // Of it, waiting: for a describing thread, and (described) for the serial commit.
  double describe_queued_ms = 0.0, commit_queued_ms = 0.0;
  std::size_t ccv_considered = 0, ccv_removed = 0;
  void addTo(nlohmann::json& line) const;
};

// What the source gave (SourceStage).
struct SourceFigures {
  bool live = false;
  std::size_t frames_bad = 0;       // unreadable frames, skipped
  bool stopped_on_request = false;  // Ctrl-C or SIGTERM ended the input early
  std::string end_problem;          // non-empty when the source ended abnormally
  // Live sources only: what the device sent and what the pipeline missed, when its stream ended.
  core::LiveStats live_stats;
  void addTo(nlohmann::json& report) const;
};

// Frames through to the sink (StatsSink).
struct StreamFigures {
  std::size_t frames = 0;                                // frames that went through the pipeline
  std::size_t interruptions = 0;                         // a live source's device went away
  std::optional<double> latency_ms_p50, latency_ms_p95;  // capture to end of fusion
  // How fast the resident memory grew over the second half of the frames (least squares),
  // MB per 1,000 frames; nothing for runs under 200 frames.
  std::optional<double> rss_growth_mb_per_1000_frames;
  double cpu_stream_s = 0.0;      // process CPU time from the start to the last frame
  double elapsed_stream_s = 0.0;  // wall time from the start to the last frame
  void addTo(nlohmann::json& report) const;
};

// The process's CPU time (user + system, every thread), split where a robot needs it: while
// frames stream, then the end of the stream (the patches left finalized, textured and
// committed), then the finish (loop closure's last solve, the TSDF correction, the export).
struct CpuFigures {
  double stream_s = 0.0, end_of_stream_s = 0.0, finish_s = 0.0;
  double elapsed_stream_s = 0.0;
  std::size_t frames = 0;
  void addTo(nlohmann::json& report) const;
};

// TrackingStage.
struct TrackingFigures {
  std::string poses;  // "track" or "gt"
  std::size_t tracking_losses = 0;
  std::size_t tracking_restarts = 0;
  std::size_t relocalisations = 0;  // found again after a loss or an interrupted source
  std::size_t feature_poses = 0;    // frames whose solve started from a feature pose
  std::size_t keyframes_made = 0;
  // Of those, kept for relocalisation and a later session (not revisits of a kept place).
  std::size_t relocalisation_keyframes = 0;
  // `--continue`: the earlier session's keyframes, and the frame first found among them.
  std::size_t continued_map_keyframes = 0;
  std::optional<long> continued_map_found_at_frame;
  void addTo(nlohmann::json& report) const;
};

// IntegrationStage.
struct IntegrationFigures {
  int holdout_every = 0;
  std::size_t frames_integrated = 0;
  std::size_t frames_without_pose = 0;  // no pose, tracking lost, or rejected
  std::size_t frames_held_out = 0;      // posed but not fused or textured (--holdout-every)
  // Tracked in a segment not (yet) joined to the map: neither fused nor textured.
  std::size_t frames_held_apart = 0;
  // Posed and searched for planes, not integrated (tsdf.integrate_every_n_frames).
  std::size_t frames_between_integrations = 0;
  std::size_t frames_shed = 0;  // of those, due but late (live: LoadShedding)
  std::size_t tsdf_bytes = 0;
  std::size_t tsdf_blocks_released = 0;  // far behind the camera (tsdf.release_distance_m)
  void addTo(nlohmann::json& report) const;
};

// PlaneStage: the patch map.
struct PlaneFigures {
  std::size_t patches_finalized = 0;    // in the map (OUT/patches.obj)
  std::size_t patch_finalizations = 0;  // every finalization, later versions included
  std::map<std::string, std::size_t> finalizations_by_reason;  // PatchEvent::reason -> count
  std::size_t patches_retired = 0;      // finalized, then merged into another patch
  std::size_t colour_samples = 0;       // held by all patches
  std::size_t colour_sample_bytes = 0;
  std::size_t samples_released = 0;  // patches whose samples left memory (and came back or not)
  std::size_t colour_frames_shed = 0;  // due for colour but late, sampled on the next frame
  std::size_t plane_searches_shed = 0;  // late frames whose plane search was left out
  // Loop-closure corrections the map followed, planes they moved and planes merged after.
  std::size_t loop_corrections_followed = 0, loop_planes_moved = 0, loop_planes_merged = 0;
  // Tiles whose cells and colours moved within their plane (patches.move_within_plane), and
  // the plane stage's time following corrections, in all.
  std::size_t loop_tiles_moved_within_planes = 0;
  double loop_follow_ms = 0.0;
  double loop_follow_frame_ms_max = 0.0;  // the most it took between two frames
  void addTo(nlohmann::json& report) const;
};

// The bitmaps of the finalized patches (their current versions), as exported.
struct BitmapFigures {
  std::size_t bitmaps = 0;
  std::size_t texels_observed = 0, texels_inpainted = 0;
  std::size_t bytes = 0;   // 3 per texel of the grids, as held in memory
  double ms_per_m2 = 0.0;  // build time over observed area, every version built
  void addTo(nlohmann::json& report) const;
};

// CommitStage: the texture database's side (docs/METRICS.md, "Matching").
struct CommitFigures {
  std::size_t textures_stored = 0;  // new textures this run stored (versions included)
  std::size_t patterns_stored = 0;
  std::size_t textures_removed = 0;  // of those, removed again: superseded, no instance left
  std::size_t commit_failures = 0;
  std::size_t retirements = 0;  // patches merged into another: their instances removed
  std::size_t ccv_considered = 0, ccv_removed = 0;
  core::Quantiles commit_latencies_ms;  // finalization to commit, per committed patch
  core::Quantiles describe_queued_ms, commit_queued_ms;  // the waits within it
  core::Quantiles store_commit_ms;      // TextureStore::commit calls alone
  StageTimer match;                     // matching and layer planning, per patch
  StageTimer describe;                  // bitmap, description and pattern, per patch
  void addTo(nlohmann::json& report) const;
};

// The map's texture economy (reuse::economyOf) under report.json's names.
void addEconomy(const reuse::Economy& economy, nlohmann::json& report);

// The database the run grew.
struct DatabaseFigures {
  std::string location;
  std::optional<db::ServerLink> server_link;  // a server's database only
  std::int64_t run_id = 0;                    // this run in the database's runs table
  std::size_t instances = 0;                  // instances (layers included) the map committed
  void addTo(nlohmann::json& report) const;
};

// Loop closure (tracked poses only): what it found, the map after it and the ATE of the
// corrected trajectory (OUT/trajectory_closed.txt).
struct LoopFigures {
  bool enabled = false;
  loop::LoopStats loops;
  std::size_t instances_retired = 0;  // patches merged after a correction, out of the database
  double wait_s = 0.0;                // the end of the stream waiting for loop closure
  std::optional<core::AteResult> ate_after_closure;  // over the corrected trajectory
  // Tracked poses left out of the corrected trajectory: their segment was never joined.
  std::size_t poses_apart = 0;
  // The TSDF fused again at the corrected poses from the frames kept per keyframe.
  bool tsdf_corrected = false;
  std::size_t tsdf_frames_kept = 0;
  std::size_t tsdf_frames_kept_bytes = 0;  // on disk while the run lasted
  double tsdf_correction_s = 0.0;
  void addTo(nlohmann::json& report) const;
};

// The exported map.
struct ExportFigures {
  std::size_t mesh_vertices = 0;
  std::size_t map_triangles = 0;  // map.obj / map.glb
  void addTo(nlohmann::json& report) const;
};

// A stage's time per call (StageTimer).
struct StageFigures {
  std::string name;
  std::size_t calls = 0;
  double mean_ms = 0.0;
  double median_ms = 0.0;
  double alone_fps = 0.0;
  double cpu_ms_mean = 0.0;  // on the thread that ran the call (StageTimer)
};

}  // namespace tessera::pipeline
