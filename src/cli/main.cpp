// The `tessera` command: one subcommand per job.
#include <spdlog/spdlog.h>
#include <CLI/CLI.hpp>

#include "db_command.h"
#include "devices_command.h"
#include "eval_command.h"
#include "match_command.h"
#include "pattern_command.h"
#include "play_command.h"
#include "record_command.h"
#include "run_command.h"
#include "tessera/core/error.h"
#include "tessera/core/log.h"

int main(int argc, char** argv) {
  CLI::App app{"tessera: compact textured maps from RGB-D sensors"};
  app.set_version_flag("--version", TESSERA_VERSION);
  app.require_subcommand(1);
  app.fallthrough();  // global options may follow the subcommand
  std::string log_level = "info";
  app.add_option("--log-level", log_level, "trace, debug, info, warn, error or off")
      ->capture_default_str();

  tessera::cli::RunArguments run_args;
  CLI::App* run = tessera::cli::addRunCommand(app, run_args);
  tessera::cli::RecordArguments record_args;
  CLI::App* record = tessera::cli::addRecordCommand(app, record_args);
  tessera::cli::PlayArguments play_args;
  CLI::App* play = tessera::cli::addPlayCommand(app, play_args);
  tessera::cli::RecordArguments synth_args;
  CLI::App* synth = tessera::cli::addSynthCommand(app, synth_args);
  tessera::cli::EvalArguments eval_args;
  CLI::App* eval = tessera::cli::addEvalCommand(app, eval_args);
  CLI::App* devices = tessera::cli::addDevicesCommand(app);
  tessera::cli::DbArguments db_args;
  CLI::App* db = tessera::cli::addDbCommand(app, db_args);
  tessera::cli::MatchArguments match_args;
  CLI::App* match = tessera::cli::addMatchCommand(app, match_args);
  tessera::cli::PatternArguments pattern_args;
  CLI::App* pattern = tessera::cli::addPatternCommand(app, pattern_args);

  CLI11_PARSE(app, argc, argv);
  try {
    tessera::core::initLogging(log_level);
  } catch (const tessera::core::Error& e) {
    fmt::print(stderr, "tessera: {}\n", e.what());
    return 2;
  }
  if (run->parsed()) return tessera::cli::runCommand(run_args);
  if (record->parsed()) return tessera::cli::recordCommand(record_args);
  if (play->parsed()) return tessera::cli::playCommand(play_args);
  if (synth->parsed()) return tessera::cli::synthCommand(synth_args);
  if (eval->parsed()) return tessera::cli::evalCommand(eval_args);
  if (devices->parsed()) return tessera::cli::devicesCommand();
  if (db->parsed()) return tessera::cli::dbCommand(*db, db_args);
  if (match->parsed()) return tessera::cli::matchCommand(match_args);
  if (pattern->parsed()) return tessera::cli::patternCommand(pattern_args);
  return 0;
}
