#pragma once
// The `planes:` (per-frame detection) and `patches:` (patch map) sections of the config file.
#include "tessera/core/config.h"
#include "tessera/planes/patch_map.h"
#include "tessera/planes/plane_detector.h"

namespace tessera::planes {

void readConfig(const core::ConfigSection& section, PlaneDetectorConfig& config);
void readConfig(const core::ConfigSection& section, PatchMapConfig& config);

}  // namespace tessera::planes
