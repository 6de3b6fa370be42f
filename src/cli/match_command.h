#pragma once
// `tessera match A.png B.png`: the cascade's verdict for two images, for tuning thresholds.
#include <string>

#include <CLI/CLI.hpp>

namespace tessera::cli {

struct MatchArguments {
  std::string query;     // A: the new bitmap
  std::string stored;    // B: as if it were in the database
  bool pattern = false;  // B is a pattern tile
  std::string config;
  std::string render;  // write B rendered through the transform onto A's grid here
  bool json = false;
};

CLI::App* addMatchCommand(CLI::App& app, MatchArguments& args);

// Exit code 0 when A reuses B, 3 when the cascade refuses, 1 on an error.
int matchCommand(const MatchArguments& args);

}  // namespace tessera::cli
