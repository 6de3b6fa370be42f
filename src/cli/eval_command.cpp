#include "eval_command.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include "tessera/core/error.h"
#include "tessera/eval/run_evaluation.h"

namespace tessera::cli {

CLI::App* addEvalCommand(CLI::App& app, EvalArguments& args) {
  CLI::App* eval = app.add_subcommand(
      "eval", "Compare a run (OUT of tessera run) with ground truth (a recording's .gt.json)");
  eval->add_option("RUN_DIR", args.run_dir, "Output folder of tessera run")
      ->required()
      ->check(CLI::ExistingDirectory);
  eval->add_option("GT", args.ground_truth, "Ground-truth file, e.g. recordings/office.gt.json")
      ->required()
      ->check(CLI::ExistingFile);
  return eval;
}

int evalCommand(const EvalArguments& args) {
  try {
    const nlohmann::json figures = eval::evaluateRun(args.run_dir, args.ground_truth);
    // One line per figure on stdout, for people and scripts alike.
    for (const auto& [key, value] : figures.items()) {
      // The per-plane and per-texture lists stay in report.json.
      if (key != "planes" && key != "textures") fmt::print("{}: {}\n", key, value.dump());
    }
    spdlog::info("ground-truth figures written into {}/report.json", args.run_dir);
    return 0;
  } catch (const core::Error& e) {
    spdlog::error("{}", e.what());
    return 1;
  }
}

}  // namespace tessera::cli
