#pragma once
// `tessera devices`: lists the live devices this host can open, with their modes.
#include <CLI/CLI.hpp>

namespace tessera::cli {

CLI::App* addDevicesCommand(CLI::App& app);

// Returns the process exit code. Errors are logged, never thrown.
int devicesCommand();

}  // namespace tessera::cli
