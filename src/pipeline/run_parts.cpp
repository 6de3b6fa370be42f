#include "internal/run_parts.h"

#include <filesystem>

namespace tessera::pipeline::internal {

namespace {

std::optional<std::size_t> framesTotal(const core::FrameSource& input, const RunOptions& options) {
  std::optional<std::size_t> total = input.frameCount();
  if (total) total = *total - std::min(*total, options.skip_frames);
  if (total && options.max_frames) total = std::min(*total, *options.max_frames);
  return total;
}

// Plane alignment corrects tracked poses only.
planes::PlaneAlignmentConfig alignmentFor(const RunConfig& config, const RunOptions& options) {
  planes::PlaneAlignmentConfig alignment = config.pose_correction;
  alignment.enabled = alignment.enabled && options.poses == PoseSource::kTrack;
  return alignment;
}

void removeDatabaseFiles(const std::filesystem::path& path) {
  for (const char* suffix : {"", "-wal", "-shm", "-journal"}) {
    std::error_code ec;
    std::filesystem::remove(path.string() + suffix, ec);
  }
}

// --db, or without it a database of the run's own, replacing one an earlier run left in OUT.
std::unique_ptr<db::TextureStore> openStore(const RunOptions& options) {
  const std::string location =
      options.db ? *options.db : (options.out_dir / "textures.db").string();
  if (!options.db) removeDatabaseFiles(location);
  db::OpenOptions db_options;
  db_options.journal = options.out_dir / "db_journal.sqlite";  // a server's database only
  return db::openTextureStore(location, db_options);
}

}  // namespace

RunParts::RunParts(core::FrameSource& input, const RunConfig& config, const RunOptions& options,
                   const SavedMap* earlier)
    : source(input),
      sample_dir(options.out_dir / "samples"),
      source_stage(input, options.max_frames, options.stop, options.skip_frames),
      loop_closer(config.loop_closure.enabled && options.poses == PoseSource::kTrack
                      ? std::make_unique<loop::LoopCloser>(config.loop_closure)
                      : nullptr),
      tracking(config.tracker, options.poses),
      integration(config.tsdf, options.threads > 0 ? options.threads : defaultThreadCount(),
                  options.holdout_every),
      planes(config.planes, config.patches, alignmentFor(config, options), loop_closer != nullptr),
      bitmaps(options.out_dir),
      sink(options.out_dir, framesTotal(input, options), options.on_progress,
           [this] { return bitmaps.bitmapBytes(); }),
      store(openStore(options)),
      run_id(store->beginRun(input.name())),
      catalog(*store, config.match),
      describe(config.textures, config.match, config.pattern, &catalog),
      commit(*store, catalog, {config.match, config.pattern, run_id}),
      map_saver(options.save_map ? std::make_unique<MapSaver>(
                                       options.out_dir, store->location(), earlier,
                                       config.pipeline.checkpoint_every_s, planes, bitmaps, commit)
                                 : nullptr),
      surface(
          integration, loop_closer.get(),
          input.isLive() ? config.pipeline.texture_nice_live : config.pipeline.texture_nice_replay),
      stages(source_stage, tracking, integration, planes, describe, commit, bitmaps, sink,
             loop_closer.get(), options.listener,
             {config.pipeline.return_freed_memory_s, config.pipeline.return_freed_memory_above_mb},
             map_saver.get(), &surface) {
  planes.spillSamplesTo(sample_dir);
  if (loop_closer) tracking.followLoopClosure();
  if (loop_closer && config.loop_closure.hold_apart_unjoined_segments) {
    integration.holdApartUnjoinedSegments();
  }
  if (loop_closer && config.tsdf.correct_after_loop_closure) {
    integration.keepFramesForCorrection(options.out_dir / "tsdf_frames");
  }
  if (options.monitor != nullptr) {
    sink.attachMonitor(options.monitor, [this] { return source_stage.framesDroppedSoFar(); });
    options.monitor->start(input.name());
  }
}

}  // namespace tessera::pipeline::internal
