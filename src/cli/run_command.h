#pragma once
// `tessera run`: replay or stream a source through the pipeline into OUT/.
#include <optional>
#include <string>

#include <CLI/CLI.hpp>

#include "source_factory.h"

namespace tessera::cli {

struct RunArguments {
  std::string source;  // empty: the default recording
  std::string config;
  std::string out_dir = "tessera_out";
  int threads = 0;
  std::string poses = "track";
  int holdout_every = 0;
  bool residual = false;
  std::string db;
  std::string monitor;        // [ADDR:]PORT of the HTTP monitor; empty: none
  std::string monitor_token;  // required by the monitor when not empty
  std::size_t skip_frames = 0;  // --skip-frames
  std::string continue_dir;     // --continue: the run folder whose saved map this run continues
  bool no_save_map = false;     // --no-save-map
  bool quiet = false;         // no progress line or periodic progress log
  // ROS 1: where to publish the map (ros://[HOST:PORT], or none); empty: a ros:// source's
  // own graph, else nowhere.
  std::string publish;
  std::string map_frame = "map";                          // --map-frame
  std::string published_camera_frame = "tessera_camera";  // --tf-camera-frame
  SourceArguments source_args;
};

// Adds the subcommand and its options to `app`; the returned arguments fill on parse.
CLI::App* addRunCommand(CLI::App& app, RunArguments& args);

// Returns the process exit code. Errors are logged, never thrown.
int runCommand(const RunArguments& args);

}  // namespace tessera::cli
