#include "tessera/pipeline/run.h"

#include <chrono>
#include <filesystem>

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include "internal/run_parts.h"
#include "internal/saved_map.h"
#include "tessera/core/cpu_time.h"
#include "tessera/core/error.h"
#include "tessera/core/memory.h"
#include "tessera/pipeline/flow_graph.h"

namespace tessera::pipeline {

namespace {

void createOutputDir(const std::filesystem::path& dir) {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec || !std::filesystem::is_directory(dir)) {
    throw core::Error(fmt::format("{}: cannot create the output folder: {}", dir.string(),
                                  ec ? ec.message() : "a file of that name exists"));
  }
}

// What the run wrote besides the map itself: the trajectories, the report and a database file
// (not a server), as absolute paths.
void addRunFiles(std::vector<std::filesystem::path>& files, const std::filesystem::path& out_dir,
                 const std::string& database_location) {
  for (const std::filesystem::path& file :
       {out_dir / "trajectory.txt", out_dir / "trajectory_closed.txt", out_dir / "report.json",
        std::filesystem::path(database_location)}) {
    std::error_code ec;
    if (std::filesystem::is_regular_file(file, ec)) files.push_back(file);
  }
  for (std::filesystem::path& file : files) {
    std::error_code ec;
    const std::filesystem::path absolute = std::filesystem::absolute(file, ec);
    if (!ec) file = absolute;
  }
}

}  // namespace

// Builds the stages (run_parts.cpp), runs them as a flow graph (flow_graph.cpp), sums up the
// run (run_summary.cpp) and exports the map (run_export.cpp).
RunSummary runPipeline(core::FrameSource& source, const RunConfig& config,
                       const RunOptions& given) {
  RunOptions options = given;
  // Returned every return_freed_memory_s instead; as many arenas as threads run at once.
  core::keepFreedMemoryForReuse(options.threads > 0 ? options.threads : defaultThreadCount());
  std::optional<internal::SavedMap> earlier;
  if (options.continue_map) {
    // Read whole before anything is written: a map that cannot be continued changes nothing.
    earlier = internal::readSavedMap(options.out_dir, config.patches, options.out_dir / "samples",
                                     options.db);
    if (!options.db) options.db = earlier->database;
    spdlog::info("continuing the map in {} (session {}): {} keyframes, {} patches",
                 (options.out_dir / "map").string(), earlier->sessions + 1,
                 earlier->keyframes.size(), earlier->patches.patches().size());
  }
  createOutputDir(options.out_dir);
  if (!options.continue_map && (options.save_map || !options.db)) {
    // A saved map from an earlier run here is not this run's: its database is replaced (no
    // --db), or this run's map takes its place at the first checkpoint.
    internal::removeSavedMap(options.out_dir);
  }
  internal::RunParts parts(source, config, options, earlier ? &*earlier : nullptr);
  if (earlier) internal::continueMap(parts, *earlier);
  const auto start = std::chrono::steady_clock::now();
  const PipelineConfig& pipeline = config.pipeline;
  const bool live = source.isLive();
  if (live) {
    const LoadShedding shedding{pipeline.live_shed_after_ms};
    parts.integration.shedLoad(shedding);
    parts.planes.shedLoad(shedding);
  }
  runGraph(parts.stages, parts.stages, parts.stages,
           {options.threads, live ? pipeline.live_frames_in_flight : pipeline.max_frames_in_flight,
            live ? pipeline.texture_nice_live : pipeline.texture_nice_replay,
            pipeline.max_patches_waiting,
            live ? static_cast<std::size_t>(pipeline.live_patches_waiting_mb * (1 << 20)) : 0,
            pipeline.describing_threads});
  parts.sink.flush();
  parts.store->finishRun(parts.run_id);  // a server's store first sends what its journal holds
  const double wall_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  const double cpu_graph_done_s = core::processCpuSeconds();
  parts.surface.wait();  // the integration stage is the summary's again

  RunSummary summary = internal::summariseRun(parts, options, wall_s);
  std::vector<std::filesystem::path> files = internal::exportRun(parts, options, summary);
  // A session not found in the map is in another frame: its trajectory and mesh are its own.
  const bool found = earlier && summary.tracking.continued_map_found_at_frame.has_value();
  if (found) {
    try {
      internal::prependEarlierTrajectory(options.out_dir, *earlier);
    } catch (const core::Error& e) {
      spdlog::error("the earlier sessions' poses are not in trajectory.txt: {}", e.what());
    }
  }
  if (parts.map_saver) {
    try {
      parts.map_saver->save();
    } catch (const std::exception& e) {
      spdlog::error("the map was not saved for --continue ({}); the earlier saved map is kept",
                    e.what());
    }
  }
  {
    std::error_code ignored;
    std::filesystem::remove_all(parts.sample_dir, ignored);
  }
  summary.peak_rss_mb = peakRssMb();
  summary.end_to_end_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  summary.cpu.stream_s = summary.stream.cpu_stream_s;
  summary.cpu.elapsed_stream_s = summary.stream.elapsed_stream_s;
  summary.cpu.frames = summary.stream.frames;
  summary.cpu.end_of_stream_s = cpu_graph_done_s - parts.sink.cpuAtLastFrameS();
  summary.cpu.finish_s = core::processCpuSeconds() - cpu_graph_done_s;
  writeReport(summary, options.out_dir / "report.json");
  if (options.monitor != nullptr) options.monitor->finish(reportJson(summary));
  if (options.listener != nullptr) {
    addRunFiles(files, options.out_dir, summary.database.location);
    options.listener->onExported(files);
  }
  return summary;
}

}  // namespace tessera::pipeline
