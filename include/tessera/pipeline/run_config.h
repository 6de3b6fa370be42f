#pragma once
// Every tunable of `tessera run`, gathered from the stages' own Config structs.
#include <filesystem>
#include <optional>

#include "tessera/core/config.h"
#include "tessera/fusion/tracker.h"
#include "tessera/fusion/tsdf_map.h"
#include "tessera/loop/loop_config.h"
#include "tessera/match/match_cascade.h"
#include "tessera/pattern/pattern_config.h"
#include "tessera/planes/patch_map.h"
#include "tessera/planes/plane_alignment.h"
#include "tessera/planes/plane_detector.h"
#include "tessera/texture/bitmap_builder.h"

namespace tessera::pipeline {

struct PipelineConfig {
  int max_frames_in_flight = 4;  // replay back-pressure: frames between source and sink
  // Live sources: frames in the pipeline at once. The device does not wait: while this many
  // are in flight its newer frames queue (OpenNi2Options::queue_frames) and the oldest drop.
  int live_frames_in_flight = 2;
  // Live sources: a frame that reaches the integration or the colour sampling more than this
  // many milliseconds after its arrival leaves out what it can (LoadShedding, stages.h);
  // 0: never.
  double live_shed_after_ms = 50.0;
  // How far (0 to 19) the nice value of the threads that describe and commit finalized
  // patches is raised above the process's, for live sources and for replay: with the cores
  // short, the frame path runs first and texturing waits for a free core; 0: not at all.
  int texture_nice_live = 10;
  int texture_nice_replay = 0;
  // Threads that build and describe the finalized patches' textures; 0: half of the run's
  // threads (--threads), at least 1. On 2 cores a second describer only took turns with the
  // frame path: 16 % more CPU a frame on the loop ring, no earlier commits.
  int describing_threads = 0;
  // Finalized patches waiting for their textures, at most: at the bound a replay's source
  // waits and a live device drops frames, so that a backlog cannot grow the memory without end.
  int max_patches_waiting = 4;
  // Live sources: the bound is the waiting patches' colour samples instead, in MB as the
  // describer lists them (20 bytes a sample; till then the jobs share the map's cells), and
  // their count is not bounded, so that a burst of finalizations, a room's surfaces seen again, is
  // textured a little later rather than costing frames. 0: max_patches_waiting applies live too.
  double live_patches_waiting_mb = 256.0;
  // Seconds between returns of the freed memory glibc keeps to the kernel (malloc_trim, after
  // a commit, off the frame path); 0: never. Frees on many threads leave free pages in many
  // arenas that glibc does not give back by itself. Unless 0, the end of the frames also
  // returns what is held and lowers the trim threshold (core::returnFreedMemorySooner).
  double return_freed_memory_s = 10.0;
  // Resident memory (MB) above which freed memory is also returned after each frame, at most
  // once a second, on the frame path (when at least 150 MB of it is not the heap in use); 0:
  // never. Bounds what glibc keeps between the returns above when finalizations come in
  // bursts.
  double return_freed_memory_above_mb = 900.0;
  // Seconds between checkpoints of OUT/map (the state `tessera run --continue` needs), written
  // on the frame path after the plane stage; a run killed outright loses at most this much of
  // its map. 0: the map is saved at the end only.
  double checkpoint_every_s = 60.0;
};

void readConfig(const core::ConfigSection& section, PipelineConfig& config);

struct RunConfig {
  PipelineConfig pipeline;
  fusion::TrackerConfig tracker;
  loop::LoopConfig loop_closure;
  fusion::TsdfConfig tsdf;
  planes::PlaneDetectorConfig planes;
  planes::PatchMapConfig patches;
  planes::PlaneAlignmentConfig pose_correction;
  texture::BitmapConfig textures;
  match::MatchConfig match;
  pattern::PatternStageConfig pattern;
};

// Reads every section of `doc` into a RunConfig and rejects unknown keys.
RunConfig readRunConfig(const core::ConfigDocument& doc);

// Defaults when `path` is empty, otherwise the file. Throws core::ConfigError.
RunConfig loadRunConfig(const std::optional<std::filesystem::path>& path);

}  // namespace tessera::pipeline
