#pragma once
// `tessera db list|show|export|import|stats|serve DB`: look into and fill a texture database.
#include <cstdint>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

namespace tessera::cli {

struct DbArguments {
  std::string db;
  std::int64_t texture_id = 0;      // show
  std::string out_dir;              // export
  std::vector<std::string> images;  // import
  bool pattern = false;             // import: each image is one tile of a repeating pattern
  std::string config;               // import: the match: settings its descriptions follow
  bool json = false;                // list, show, stats: one JSON object instead of text
  std::string listen = "8080";      // serve: [ADDR:]PORT
  std::string token;                // serve: bearer token required when not empty
  std::string destination;          // copy: the database to copy into
  double wait_s = 60.0;             // flush: how long to wait for the server
};

// Adds `db` with its subcommands; returns the `db` command.
CLI::App* addDbCommand(CLI::App& app, DbArguments& args);

// Returns the process exit code. Errors are logged, never thrown.
int dbCommand(const CLI::App& db, const DbArguments& args);

}  // namespace tessera::cli
