#pragma once
// The scene part of a recording's ground truth (.gt.json): planes, textures, sensor.
#include <nlohmann/json.hpp>

#include "tessera/drivers/synthetic/scene.h"

namespace tessera::drivers::synthetic {

// {"scene": name, "sensor": {...}, "textures": [...], "planes": [...]}; see docs/SCENES.md.
nlohmann::json sceneGroundTruth(const Scene& scene);

}  // namespace tessera::drivers::synthetic
