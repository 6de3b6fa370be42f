#pragma once
// The `pattern:` section of the configuration.
#include "tessera/core/config.h"
#include "tessera/pattern/pattern_extractor.h"

namespace tessera::pattern {

// Whether the pipeline looks for patterns in bitmaps that matched nothing, and how.
struct PatternStageConfig {
  bool enabled = true;
  PatternConfig extractor;
  // Overlays with a box at least this many texels a side and of this area become their own
  // textures, in a box grown by overlay_margin_px; thinner blobs (where a neighbouring surface
  // bleeds into the bitmap's edge) stay with the pattern and count against its fidelity.
  int min_overlay_side_px = 8;
  int min_overlay_area_px = 256;
  int overlay_margin_px = 2;
};

// Reads the `pattern:` keys; throws core::ConfigError on a value out of range.
void readConfig(const core::ConfigSection& section, PatternStageConfig& config);

}  // namespace tessera::pattern
