#pragma once
// `tessera run`: replay or stream a source through the pipeline into OUT/.
#include <optional>
#include <string>

#include <CLI/CLI.hpp>

namespace tessera::cli {

struct RunArguments {
  std::string source;  // empty: the default recording
  std::string config;
  std::string out_dir = "tessera_out";
  int threads = 0;
  std::string intrinsics;
  double depth_units_per_m = 0.0;  // 0: the layout's own
  std::size_t max_frames = 0;      // 0: all
};

// Adds the subcommand and its options to `app`; the returned arguments fill on parse.
CLI::App* addRunCommand(CLI::App& app, RunArguments& args);

// Returns the process exit code. Errors are logged, never thrown.
int runCommand(const RunArguments& args);

}  // namespace tessera::cli
