#include "tessera/reuse/map_economy.h"

#include <set>

namespace tessera::reuse {

Economy economyOf(const std::map<int, ShownPatch>& patches) {
  Economy economy;
  std::set<std::int64_t> counted;  // each stored texture takes its pixels once
  for (const auto& [id, patch] : patches) {
    economy.pixels_before += patch.pixels;
    if (patch.layers.empty()) {
      economy.pixels_after += patch.pixels;
      continue;
    }
    for (const ShownLayer& layer : patch.layers) {
      if (layer.reused) (layer.pattern ? economy.patterns_matched : economy.textures_matched) += 1;
      if (counted.insert(layer.texture_id).second) economy.pixels_after += layer.pixels;
    }
    const ShownLayer& base = patch.layers.front();
    economy.textured_patches += 1;
    economy.reuses += base.reused ? 1 : 0;
    economy.overlays += patch.layers.size() - 1;
    if (base.psnr_db) economy.shown_psnrs_db.push_back(*base.psnr_db);
  }
  return economy;
}

}  // namespace tessera::reuse
