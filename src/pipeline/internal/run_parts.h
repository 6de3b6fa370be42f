#pragma once
// What one `tessera run` builds: its stages, the texture database and the graph's view of them
// (run_stages.h), and the two steps after the graph: summing up the run and exporting the map.
#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <vector>

#include "internal/corrected_surface.h"
#include "internal/run_stages.h"
#include "internal/saved_map.h"
#include "tessera/db/texture_store.h"
#include "tessera/pipeline/run.h"
#include "tessera/reuse/store_catalog.h"

namespace tessera::pipeline::internal {

// Members are built in the order they are declared, each from those above it.
struct RunParts {
  // `earlier`: the saved map the run continues, if any (options.continue_map).
  RunParts(core::FrameSource& input, const RunConfig& config, const RunOptions& options,
           const SavedMap* earlier = nullptr);
  RunParts(const RunParts&) = delete;
  RunParts& operator=(const RunParts&) = delete;

  core::FrameSource& source;
  // Finalized patches' colour samples wait here while out of memory; removed at the end.
  std::filesystem::path sample_dir;
  SourceStage source_stage;
  // Tracked poses with loop closure on: closes loops on its own thread, fed with keyframes
  // (through `stages`).
  std::unique_ptr<loop::LoopCloser> loop_closer;
  TrackingStage tracking;
  IntegrationStage integration;
  PlaneStage planes;
  BitmapFiles bitmaps;
  StatsSink sink;
  std::unique_ptr<db::TextureStore> store;
  std::int64_t run_id;
  reuse::StoreCatalog catalog;
  DescribeStage describe;
  CommitStage commit;
  std::unique_ptr<MapSaver> map_saver;  // null unless options.save_map
  CorrectedSurface surface;             // OUT/mesh.ply's
  RunStages stages;  // the graph's view of the stages above
};

// The run's figures once the graph is done (wall_s: the graph's time); also finishes loop
// closure and writes OUT/trajectory_closed.txt when it ran.
RunSummary summariseRun(RunParts& parts, const RunOptions& options, double wall_s);

// Writes the map: OUT/mesh.ply, the bitmaps still in memory, the database textures the map
// shows, patches.obj/json, map.obj and map.glb; adds their figures to `summary`. Returns the
// map's files (mesh, patches and map models), not the textures they name.
std::vector<std::filesystem::path> exportRun(RunParts& parts, const RunOptions& options,
                                             RunSummary& summary);

}  // namespace tessera::pipeline::internal
