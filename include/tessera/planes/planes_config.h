#pragma once
// The `planes:` (per-frame detection), `patches:` (patch map) and `pose_correction:` (drift
// correction against the patches) sections of the config file.
#include "tessera/core/config.h"
#include "tessera/planes/patch_map.h"
#include "tessera/planes/plane_alignment.h"
#include "tessera/planes/plane_detector.h"

namespace tessera::planes {

void readConfig(const core::ConfigSection& section, PlaneDetectorConfig& config);
void readConfig(const core::ConfigSection& section, PatchMapConfig& config);
void readConfig(const core::ConfigSection& section, PlaneAlignmentConfig& config);

}  // namespace tessera::planes
