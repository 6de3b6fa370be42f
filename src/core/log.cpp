#include "tessera/core/log.h"

#include <fmt/format.h>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include "tessera/core/error.h"

namespace tessera::core {

void initLogging(const std::string& level) {
  const spdlog::level::level_enum parsed = spdlog::level::from_str(level);
  if (parsed == spdlog::level::off && level != "off") {
    throw ConfigError(
        fmt::format("unknown log level '{}' (use trace, debug, info, warn, error or off)", level));
  }
  spdlog::drop("tessera");  // allow re-initialisation (tests, repeated runs)
  auto logger = spdlog::stderr_color_mt("tessera");
  logger->set_pattern("[%H:%M:%S.%e] [%^%l%$] %v");
  logger->set_level(parsed);
  spdlog::set_default_logger(logger);
}

}  // namespace tessera::core
