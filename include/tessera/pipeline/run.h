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
#include "tessera/pipeline/run_config.h"
#include "tessera/pipeline/run_listener.h"
#include "tessera/pipeline/stage_figures.h"
#include "tessera/pipeline/stages.h"

namespace tessera::pipeline {

struct RunOptions {
  std::filesystem::path out_dir = "tessera_out";
  int threads = 0;  // 0: hardware threads
  PoseSource poses = PoseSource::kTrack;
  std::optional<std::size_t> max_frames;
  std::size_t skip_frames = 0;  // the source's first frames (readable or not) dropped
  int holdout_every = 0;  // every N-th frame is posed only, for eval's held-out views (0: none)
  bool residual = false;  // map.obj / map.glb also get the non-planar rest of the TSDF surface
  // The texture database the run grows (or reuses from earlier runs); OUT/textures.db when
  // not given. A postgresql:// URL opens a PostgreSQL database shared by several runs; while
  // its server is away, commits wait in OUT/db_journal.sqlite.
  std::optional<std::string> db;
  StatsSink::ProgressCallback on_progress;  // may be empty
  // Updated with every frame and commit, and given report.json at the end (may be null).
  MapMonitor* monitor = nullptr;
  // Told every pose, committed or retired patch and the exported files (may be null).
  RunListener* listener = nullptr;
  const std::atomic<bool>* stop = nullptr;  // set (e.g. by Ctrl-C) to end the stream early
  // Writes OUT/map at the end, for a later run to continue (internal/saved_map.h).
  bool save_map = true;
  // Continues the map saved in out_dir (`tessera run --continue DIR`): its keyframes, patches,
  // bitmaps and database; the first frames are relocalised in it.
  bool continue_map = false;
};

// The run's figures: each stage's own (stage_figures.h), side by side. report.json is each of
// them writing its keys (docs/METRICS.md).
struct RunSummary {
  std::string source;
  double wall_s = 0.0;
  double fps = 0.0;
  // From the first frame to the map written (the mesh, the exports and the saved map too).
  double end_to_end_s = 0.0;
  double peak_rss_mb = 0.0;
  StreamFigures stream;
  CpuFigures cpu;
  SourceFigures input;
  TrackingFigures tracking;
  IntegrationFigures integration;
  PlaneFigures patches;
  BitmapFigures bitmaps;
  CommitFigures commits;
  reuse::Economy economy;  // the map as exported (docs/METRICS.md, "Texture economy")
  DatabaseFigures database;
  // ATE of the fused poses against the recording's ground truth, when it has one; loop
  // closure's corrected trajectory has its own (`loops`). The TSDF was fused at these poses.
  std::optional<core::AteResult> ate;
  LoopFigures loops;
  ExportFigures exported;
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
