#include "tessera/planes/colour_samples.h"

#include <algorithm>
#include <cmath>

namespace tessera::planes {

ColourSamples::ColourSamples(double cell_m, int per_cell)
    : inverse_cell_(static_cast<float>(1.0 / cell_m)),
      per_cell_(std::max(1, per_cell)) {}

ColourSamples& ColourSamples::operator=(const ColourSamples& other) {
  inverse_cell_ = other.inverse_cell_;
  per_cell_ = other.per_cell_;
  tiles_ = other.tiles_;
  size_ = other.size_;
  last_tile_ = nullptr;  // it pointed into the other object's tiles
  return *this;
}

ColourSamples& ColourSamples::operator=(ColourSamples&& other) noexcept {
  inverse_cell_ = other.inverse_cell_;
  per_cell_ = other.per_cell_;
  tiles_ = std::move(other.tiles_);
  size_ = other.size_;
  last_tile_ = nullptr;
  other.tiles_.clear();
  other.size_ = 0;
  other.last_tile_ = nullptr;
  return *this;
}

std::vector<ColourSample>& ColourSamples::tileAt(int tile_u, int tile_v) {
  const std::int64_t key =
      (static_cast<std::int64_t>(tile_u) << 32) ^ static_cast<std::uint32_t>(tile_v);
  if (last_tile_ != nullptr && key == last_key_) return *last_tile_;
  auto [it, inserted] = tiles_.try_emplace(key);
  if (inserted) it->second.resize(static_cast<std::size_t>(kTileCells * kTileCells * per_cell_));
  last_key_ = key;
  last_tile_ = &it->second;
  return it->second;
}

void ColourSamples::add(const ColourSample& sample) {
  const int cu = static_cast<int>(std::floor(sample.u * inverse_cell_));
  const int cv = static_cast<int>(std::floor(sample.v * inverse_cell_));
  // kTileCells is 32: an arithmetic shift is a floor division, so negative cells land in the
  // right tile, and the low bits are the cell within it.
  static_assert(kTileCells == 32);
  std::vector<ColourSample>& tile = tileAt(cu >> 5, cv >> 5);
  ColourSample* slots = tile.data() + ((cv & 31) * kTileCells + (cu & 31)) * per_cell_;
  ColourSample* lightest = slots;
  for (int i = 1; i < per_cell_; ++i) {
    if (slots[i].score < lightest->score) lightest = slots + i;
  }
  if (lightest->score >= sample.score) return;
  if (lightest->score == ColourSample::kEmpty) ++size_;
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
      if (sample.score != ColourSample::kEmpty) samples.push_back(sample);
    }
  }
  return samples;
}

}  // namespace tessera::planes
