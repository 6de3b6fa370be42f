#pragma once
// `tessera pattern IMAGE`: the pattern extractor's verdict, lattice, tile and fidelity.
#include <string>

#include <CLI/CLI.hpp>

namespace tessera::cli {

struct PatternArguments {
  std::string image;
  std::string config;
  std::string out;  // write the tile here
  bool json = false;
};

CLI::App* addPatternCommand(CLI::App& app, PatternArguments& args);

// Exit code 0 when the image is periodic, 3 when it is not, 1 on an error.
int patternCommand(const PatternArguments& args);

}  // namespace tessera::cli
