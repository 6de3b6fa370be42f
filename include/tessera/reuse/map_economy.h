#pragma once
// The texture economy of a map (docs/METRICS.md, "Texture economy"): what its patches would
// take stored one by one against what the textures they show take, each stored texture once.
// One function, used for the live figures (after every commit) and for report.json.
#include <cstddef>
#include <cstdint>
#include <map>
#include <optional>
#include <vector>

namespace tessera::reuse {

// One layer a patch shows: a stored texture, with its size.
struct ShownLayer {
  std::int64_t texture_id = 0;
  std::size_t pixels = 0;         // of the stored image
  bool pattern = false;           // one period of a periodic pattern
  bool reused = false;            // stored before this patch's commit
  std::optional<double> psnr_db;  // fidelity of the patch as shown (a reuse or a pattern)
};

// A patch as the map shows it: its own bitmap (`layers` empty) or stored textures, layer 0
// first.
struct ShownPatch {
  std::size_t pixels = 0;  // texels of the patch's own bitmap
  std::vector<ShownLayer> layers;
};

struct Economy {
  std::size_t textured_patches = 0;  // patches shown through stored textures
  std::size_t reuses = 0;            // ... whose layer 0 was stored before them
  // Layers that reuse a stored texture, by kind (a pattern's tile, or any other texture).
  std::size_t textures_matched = 0, patterns_matched = 0;
  std::size_t overlays = 0;  // layers above layer 0
  // Texels before reuse (every patch its own bitmap) and after (each texture shown once, and
  // the bitmaps of patches shown through none).
  std::size_t pixels_before = 0, pixels_after = 0;
  std::vector<double> shown_psnrs_db;  // layer 0's fidelity, where it is not the own bitmap
};

// `patches` by patch id.
Economy economyOf(const std::map<int, ShownPatch>& patches);

}  // namespace tessera::reuse
