#include "tessera/planes/colour_samples.h"

#include <algorithm>
#include <cmath>

namespace tessera::planes {

ColourSamples::ColourSamples(double cell_m, int per_cell)
    : cell_m_(cell_m), per_cell_(std::max(1, per_cell)) {}

std::vector<ColourSample>& ColourSamples::tileAt(int tile_u, int tile_v) {
  const std::int64_t key =
      (static_cast<std::int64_t>(tile_u) << 32) ^ static_cast<std::uint32_t>(tile_v);
  auto [it, inserted] = tiles_.try_emplace(key);
  if (inserted) it->second.resize(static_cast<std::size_t>(kTileCells * kTileCells * per_cell_));
  return it->second;
}

void ColourSamples::add(const ColourSample& sample) {
  const int cu = static_cast<int>(std::floor(sample.u / cell_m_));
  const int cv = static_cast<int>(std::floor(sample.v / cell_m_));
  // Floor division, so negative cells land in the right tile.
  const int tu = cu >= 0 ? cu / kTileCells : (cu + 1) / kTileCells - 1;
  const int tv = cv >= 0 ? cv / kTileCells : (cv + 1) / kTileCells - 1;
  std::vector<ColourSample>& tile = tileAt(tu, tv);
  const int cell = (cv - tv * kTileCells) * kTileCells + (cu - tu * kTileCells);
  const auto first = tile.begin() + static_cast<std::ptrdiff_t>(cell * per_cell_);
  const auto lightest = std::min_element(
      first, first + per_cell_,
      [](const ColourSample& a, const ColourSample& b) { return a.weight < b.weight; });
  if (lightest->weight >= sample.weight) return;
  if (lightest->weight == 0.0F) ++size_;
  *lightest = sample;
}

std::size_t ColourSamples::bytes() const {
  return tiles_.size() * static_cast<std::size_t>(kTileCells * kTileCells * per_cell_) *
         sizeof(ColourSample);
}

std::vector<ColourSample> ColourSamples::all() const {
  std::vector<ColourSample> samples;
  samples.reserve(size_);
  for (const auto& [key, tile] : tiles_) {
    for (const ColourSample& sample : tile) {
      if (sample.weight > 0.0F) samples.push_back(sample);
    }
  }
  return samples;
}

}  // namespace tessera::planes
