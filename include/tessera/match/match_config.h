#pragma once
// The `match:` section of the configuration.
#include "tessera/core/config.h"
#include "tessera/match/match_cascade.h"

namespace tessera::match {

// Reads the `match:` keys; throws core::ConfigError on a value out of range.
void readConfig(const core::ConfigSection& section, MatchConfig& config);

}  // namespace tessera::match
