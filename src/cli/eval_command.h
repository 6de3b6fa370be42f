#pragma once
// `tessera eval RUN_DIR [GT.json] [--frames SOURCE]`: ground-truth and view figures for a run.
#include <string>

#include <CLI/CLI.hpp>

#include "source_factory.h"
#include "tessera/eval/plane_evaluation.h"
#include "tessera/eval/view_evaluation.h"

namespace tessera::cli {

struct EvalArguments {
  std::string run_dir;
  std::string ground_truth;
  std::string frames;  // --frames: the source whose captured frames the map is rendered into
  std::string save_dir;
  std::string map_file = "patches.obj";  // --map
  std::string unmatched_run;             // --unmatched
  int max_views = 20;
  int edge_margin_px = eval::ViewEvaluationOptions{}.edge_margin_px;
  std::string pose_time = "colour";  // --pose-time: colour or depth
  double plane_offset_m = eval::PlaneEvaluationOptions{}.max_offset_m;      // --plane-offset-m
  double plane_normal_deg = eval::PlaneEvaluationOptions{}.max_normal_deg;  // --plane-normal-deg
  SourceArguments source_args;
};

CLI::App* addEvalCommand(CLI::App& app, EvalArguments& args);

// Returns the process exit code. Errors are logged, never thrown.
int evalCommand(const EvalArguments& args);

}  // namespace tessera::cli
