#include "tessera/pipeline/run_config.h"

#include "tessera/core/error.h"
#include "tessera/match/match_config.h"
#include "tessera/planes/planes_config.h"

namespace tessera::pipeline {

void readConfig(const core::ConfigSection& section, PipelineConfig& config) {
  section.read("max_frames_in_flight", config.max_frames_in_flight);
  section.read("live_frames_in_flight", config.live_frames_in_flight);
  section.read("live_shed_after_ms", config.live_shed_after_ms);
  section.read("texture_nice_live", config.texture_nice_live);
  section.read("texture_nice_replay", config.texture_nice_replay);
  section.read("describing_threads", config.describing_threads);
  section.read("max_patches_waiting", config.max_patches_waiting);
  section.read("live_patches_waiting_mb", config.live_patches_waiting_mb);
  section.read("return_freed_memory_s", config.return_freed_memory_s);
  section.read("return_freed_memory_above_mb", config.return_freed_memory_above_mb);
  section.read("checkpoint_every_s", config.checkpoint_every_s);
  if (!(config.return_freed_memory_s >= 0.0) || !(config.return_freed_memory_above_mb >= 0.0) ||
      !(config.checkpoint_every_s >= 0.0) || !(config.live_shed_after_ms >= 0.0) ||
      !(config.live_patches_waiting_mb >= 0.0)) {
    throw core::ConfigError(
        "pipeline: return_freed_memory_s, return_freed_memory_above_mb, checkpoint_every_s, "
        "live_shed_after_ms and live_patches_waiting_mb must be 0 or more");
  }
  if (config.describing_threads < 0) {
    throw core::ConfigError("pipeline: describing_threads must be 0 (half the threads) or more");
  }
  if (config.max_frames_in_flight < 1 || config.live_frames_in_flight < 1 ||
      config.max_patches_waiting < 1) {
    throw core::ConfigError(
        "pipeline: max_frames_in_flight, live_frames_in_flight and max_patches_waiting must be "
        "at least 1");
  }
  for (const int nice : {config.texture_nice_live, config.texture_nice_replay}) {
    if (nice < 0 || nice > 19) {
      throw core::ConfigError(
          "pipeline: texture_nice_live and texture_nice_replay must be 0 to 19");
    }
  }
}

RunConfig readRunConfig(const core::ConfigDocument& doc) {
  RunConfig config;
  const core::ConfigSection root = doc.root();
  try {
    readConfig(root.section("pipeline"), config.pipeline);
    fusion::readConfig(root.section("tracker"), config.tracker);
    fusion::readConfig(root.section("tracker_features"), config.tracker.features);
    loop::readConfig(root.section("loop_closure"), config.loop_closure);
    fusion::readConfig(root.section("loop_features"), config.loop_closure.features);
    fusion::readConfig(root.section("tsdf"), config.tsdf);
    planes::readConfig(root.section("planes"), config.planes);
    planes::readConfig(root.section("patches"), config.patches);
    planes::readConfig(root.section("pose_correction"), config.pose_correction);
    texture::readConfig(root.section("textures"), config.textures);
    match::readConfig(root.section("match"), config.match);
    pattern::readConfig(root.section("pattern"), config.pattern);
  } catch (const core::ConfigError& e) {
    const std::string message = e.what();
    // Range checks inside the stages do not know the file; add it.
    if (message.rfind(doc.origin(), 0) == 0) throw;
    throw core::ConfigError(doc.origin() + ": " + message);
  }
  doc.checkAllKeysUsed();
  return config;
}

RunConfig loadRunConfig(const std::optional<std::filesystem::path>& path) {
  return readRunConfig(path ? core::ConfigDocument::load(*path) : core::ConfigDocument::empty());
}

}  // namespace tessera::pipeline
