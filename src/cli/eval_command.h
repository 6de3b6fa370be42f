#pragma once
// `tessera eval RUN_DIR GT.json`: ground-truth figures for a run.
#include <string>

#include <CLI/CLI.hpp>

namespace tessera::cli {

struct EvalArguments {
  std::string run_dir;
  std::string ground_truth;
};

CLI::App* addEvalCommand(CLI::App& app, EvalArguments& args);

// Returns the process exit code. Errors are logged, never thrown.
int evalCommand(const EvalArguments& args);

}  // namespace tessera::cli
