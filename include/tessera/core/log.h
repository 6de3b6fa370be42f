#pragma once
// Logging goes through spdlog's default logger; this sets it up once for the process.
#include <string>

namespace tessera::core {

// Logs to stderr at `level` ("trace", "debug", "info", "warn", "error", "off").
// Throws ConfigError on an unknown level.
void initLogging(const std::string& level);

}  // namespace tessera::core
