#pragma once
// `tessera run` as a library call: source in, OUT/ files and a summary out.
#include <atomic>
#include <cstddef>
#include <filesystem>
#include <optional>
#include <string>

#include <nlohmann/json.hpp>

#include "tessera/core/frame_source.h"
#include "tessera/core/trajectory.h"
#include "tessera/db/texture_store.h"
#include "tessera/loop/loop_graph.h"
#include "tessera/pipeline/run_config.h"
#include "tessera/pipeline/stages.h"

namespace tessera::pipeline {

struct RunOptions {
  std::filesystem::path out_dir = "tessera_out";
  int threads = 0;  // 0: hardware threads
  PoseSource poses = PoseSource::kTrack;
  std::optional<std::size_t> max_frames;
  int holdout_every = 0;  // every N-th frame is posed only, for eval's held-out views (0: none)
  bool residual = false;  // map.obj / map.glb also get the non-planar rest of the TSDF surface
  // The texture database the run grows (or reuses from earlier runs); OUT/textures.db when
  // not given. A postgresql:// URL opens a PostgreSQL database shared by several runs; while
  // its server is away, commits wait in OUT/db_journal.sqlite.
  std::optional<std::string> db;
  StatsSink::ProgressCallback on_progress;  // may be empty
  // Updated with every frame and commit, and given report.json at the end (may be null).
  MapMonitor* monitor = nullptr;
  const std::atomic<bool>* stop = nullptr;  // set (e.g. by Ctrl-C) to end the stream early
};

struct StageFigures {
  std::string name;
  std::size_t calls = 0;
  double mean_ms = 0.0;
  double median_ms = 0.0;
  double alone_fps = 0.0;
};

struct RunSummary {
  std::string source;
  std::size_t frames = 0;      // frames that went through the pipeline
  std::size_t frames_bad = 0;  // unreadable frames, skipped
  std::size_t frames_integrated = 0;
  std::size_t frames_without_pose = 0;  // not integrated: no pose, tracking lost, or rejected
  int holdout_every = 0;
  std::size_t frames_held_out = 0;  // posed but not fused or textured (--holdout-every)
  // Posed and searched for planes, not integrated (tsdf.integrate_every_n_frames).
  std::size_t frames_between_integrations = 0;
  std::string poses;  // "track" or "gt"
  std::size_t tracking_losses = 0;
  std::size_t tracking_restarts = 0;
  std::size_t relocalisations = 0;  // tracking found again against a recent keyframe
  std::size_t feature_poses = 0;    // frames posed from features first (large motion)
  std::string source_end_problem;   // non-empty when the source ended abnormally
  bool stopped_on_request = false;  // Ctrl-C or SIGTERM ended the input early
  // Live sources only (docs/METRICS.md): what the device sent and what the pipeline missed.
  bool live = false;
  core::LiveStats live_stats;
  std::size_t source_interruptions = 0;
  std::optional<double> latency_ms_p50;  // capture (arrival at the host) to end of fusion
  std::optional<double> latency_ms_p95;
  double wall_s = 0.0;
  double fps = 0.0;
  double peak_rss_mb = 0.0;
  std::optional<double> rss_growth_mb_per_1000_frames;  // over the second half of the frames
  std::size_t tsdf_bytes = 0;
  std::size_t tsdf_blocks_released = 0;  // far behind the camera (tsdf.release_distance_m)
  // The paper's summary (docs/METRICS.md): layers of the map that reuse a stored texture, by
  // kind (a pattern tile, or any other texture).
  std::size_t textures_matched = 0, patterns_matched = 0;
  std::size_t mesh_vertices = 0;
  std::size_t map_triangles = 0;        // map.obj / map.glb
  std::size_t patches_finalized = 0;    // in the map at the end (OUT/patches.obj)
  std::size_t patch_finalizations = 0;  // every finalization, later versions included
  std::size_t patches_retired = 0;      // finalized, then merged into another patch
  std::size_t colour_samples = 0;       // held by all patches at the end
  std::size_t colour_sample_bytes = 0;
  std::size_t samples_released = 0;  // patches whose samples left memory (and came back or not)
  // Bitmaps of the finalized patches (their current versions), as exported.
  std::size_t bitmaps = 0;
  std::size_t bitmap_texels_observed = 0;
  std::size_t bitmap_texels_inpainted = 0;
  std::size_t bitmap_bytes = 0;   // 3 bytes per texel of the grids, as held in memory
  double bitmap_ms_per_m2 = 0.0;  // build time over observed area, every version built
  // The texture database (docs/METRICS.md, "Texture economy" and "Matching").
  std::string db;
  std::optional<db::ServerLink> server_link;  // a server's database only
  std::int64_t db_run_id = 0;                 // this run in the database's runs table
  std::size_t db_instances = 0;               // instances (layers included) the map committed
  std::size_t textures_stored = 0;  // new textures this run stored (versions included)
  std::size_t patterns_stored = 0;
  std::size_t overlays = 0;          // overlay layers the map draws on patterned patches
  std::size_t textured_patches = 0;  // finalized patches with a committed instance
  std::size_t reuses = 0;            // ... of which reuse a texture stored before them
  std::size_t commit_failures = 0;
  std::size_t pixels_before = 0, pixels_after = 0;
  std::vector<double> shown_psnrs_db;  // fidelity of each reuse or pattern in the map
  std::size_t ccv_considered = 0, ccv_removed = 0;
  std::optional<double> commit_latency_ms_p50, commit_latency_ms_p95;
  // TextureStore::commit calls alone (the database's part of the latency above).
  std::optional<double> db_commit_ms_p50, db_commit_ms_p95;
  std::optional<double> match_ms_p50;
  // ATE of the fused poses against the recording's ground truth, when it has one.
  std::optional<core::AteResult> ate;
  // Loop closure (tracked poses only): what it found, and the ATE of the corrected trajectory
  // (OUT/trajectory_closed.txt), in whose frame the patch map ends; `ate` stays that of the
  // poses before loop closure (OUT/trajectory.txt), at which the TSDF was fused.
  bool loop_closure = false;
  loop::LoopStats loops;
  // The map after loop closure: corrections it followed, planes moved, planes merged into
  // another (a place mapped twice), and their patches' instances removed from the database.
  std::size_t loop_corrections_followed = 0, loop_planes_moved = 0, loop_planes_merged = 0;
  std::size_t loop_instances_retired = 0;
  double loop_wait_s = 0.0;  // the end of the stream waiting for loop closure (in wall_s)
  std::optional<core::AteResult> ate_after_closure;
  std::vector<StageFigures> stages;
};

// Runs the whole pipeline and writes OUT/mesh.ply, OUT/stats.jsonl and OUT/report.json.
// Throws core::Error naming the file when an output cannot be written.
RunSummary runPipeline(core::FrameSource& source, const RunConfig& config,
                       const RunOptions& options);

// The report.json object (docs/METRICS.md): figures this stage cannot compute are null.
nlohmann::json reportJson(const RunSummary& summary);
// Writes reportJson(summary) to `path`; throws core::Error when it cannot.
void writeReport(const RunSummary& summary, const std::filesystem::path& path);

// Peak resident set size of this process so far, in MB.
double peakRssMb();

}  // namespace tessera::pipeline
