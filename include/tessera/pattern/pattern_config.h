#pragma once
// The `pattern:` section of the configuration.
#include "tessera/core/config.h"
#include "tessera/pattern/pattern_extractor.h"

namespace tessera::pattern {

// Whether the pipeline looks for patterns in bitmaps that matched nothing, and how.
struct PatternStageConfig {
  bool enabled = true;
  PatternConfig extractor;
};

// Reads the `pattern:` keys; throws core::ConfigError on a value out of range.
void readConfig(const core::ConfigSection& section, PatternStageConfig& config);

}  // namespace tessera::pattern
