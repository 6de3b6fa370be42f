#pragma once
// `tessera play SOURCE ros://[HOST:PORT]`: publishes a recording on a ROS 1 graph as a camera
// driver would, at the pace it was recorded, to stand in for the camera in tests.
#include <string>

#include <CLI/CLI.hpp>

#include "source_factory.h"

namespace tessera::cli {

struct PlayArguments {
  std::string source;
  std::string target = "ros://";
  double rate = 1.0;                  // 2: twice as fast as recorded
  std::size_t skip = 0;               // frames left out at the start
  double wait_for_subscriber_s = 10;  // before the first frame
  bool preload = false;               // read every frame before publishing the first
  std::string depth_encoding = "16UC1";
  std::string colour_encoding = "rgb8";
  std::string compressed;  // "" raw images, or png / jpeg transports
  SourceArguments source_args;
};

CLI::App* addPlayCommand(CLI::App& app, PlayArguments& args);
// Returns the process exit code. Errors are logged, never thrown.
int playCommand(const PlayArguments& args);

}  // namespace tessera::cli
