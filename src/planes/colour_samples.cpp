#include "tessera/planes/colour_samples.h"

#include <algorithm>
#include <cmath>
#include <fstream>

#include <fmt/format.h>

#include "tessera/core/error.h"

namespace tessera::planes {

namespace {

// kTileCells is 32: an arithmetic shift is a floor division, so negative cells land in the
// right tile, and the low bits are the cell within it.
constexpr int kTileShift = 5;
constexpr int kCellMask = 31;

// Rounded conversions of values already within range (a mean of values in range stays in it);
// the clamp guards float rounding only. This runs for every sampled pixel: no lround.
std::uint16_t fixed88(float value) {
  return static_cast<std::uint16_t>(std::clamp(value * 256.0F + 0.5F, 0.0F, 65535.0F));
}

std::uint8_t fraction255(float value) {
  return static_cast<std::uint8_t>(std::clamp(value * 255.0F + 0.5F, 0.0F, 255.0F));
}

}  // namespace

ColourSamples::ColourSamples(double cell_m)
    : cell_m_(static_cast<float>(cell_m)), inverse_cell_(static_cast<float>(1.0 / cell_m)) {}

ColourSamples& ColourSamples::operator=(const ColourSamples& other) {
  cell_m_ = other.cell_m_;
  inverse_cell_ = other.inverse_cell_;
  tiles_ = other.tiles_;
  size_ = other.size_;
  last_tile_ = nullptr;  // it pointed into the other object's tiles
  return *this;
}

ColourSamples& ColourSamples::operator=(ColourSamples&& other) noexcept {
  cell_m_ = other.cell_m_;
  inverse_cell_ = other.inverse_cell_;
  tiles_ = std::move(other.tiles_);
  size_ = other.size_;
  last_tile_ = nullptr;
  other.tiles_.clear();
  other.size_ = 0;
  other.last_tile_ = nullptr;
  return *this;
}

std::int64_t ColourSamples::keyOf(int tile_u, int tile_v) {
  return (static_cast<std::int64_t>(tile_u) << 32) ^ static_cast<std::uint32_t>(tile_v);
}

std::vector<ColourSamples::Cell>& ColourSamples::tileAt(int tile_u, int tile_v) {
  const std::int64_t key = keyOf(tile_u, tile_v);
  if (last_tile_ != nullptr && key == last_key_) return *last_tile_;
  auto [it, inserted] = tiles_.try_emplace(key);
  if (inserted) it->second.resize(static_cast<std::size_t>(kTileCells * kTileCells));
  last_key_ = key;
  last_tile_ = &it->second;
  return it->second;
}

void ColourSamples::add(const ColourSample& sample) {
  // Weights stay within float range whatever the score (a merge passes summed weights).
  add(sample.u, sample.v, sample.rgb, std::exp(std::clamp(sample.score, -60.0F, 60.0F)));
}

void ColourSamples::add(float u, float v, const std::array<std::uint8_t, 3>& rgb, float weight) {
  const float cell_u = u * inverse_cell_, cell_v = v * inverse_cell_;
  const int cu = static_cast<int>(std::floor(cell_u));
  const int cv = static_cast<int>(std::floor(cell_v));
  static_assert(kTileCells == 1 << kTileShift);
  Cell& cell = tileAt(
      cu >> kTileShift,
      cv >> kTileShift)[static_cast<std::size_t>((cv & kCellMask) * kTileCells + (cu & kCellMask))];
  const float at_u = cell_u - static_cast<float>(cu), at_v = cell_v - static_cast<float>(cv);
  if (cell.weight <= 0.0F) {
    ++size_;
    cell.weight = weight;
    for (int c = 0; c < 3; ++c) cell.rgb[c] = fixed88(rgb[c]);
    cell.at = {fraction255(at_u), fraction255(at_v)};
    return;
  }
  // Running weighted mean: m += w / (W + w) * (x - m).
  cell.weight += weight;
  const float share = weight / cell.weight;
  for (int c = 0; c < 3; ++c) {
    const float mean = cell.rgb[c] / 256.0F;
    cell.rgb[c] = fixed88(mean + share * (static_cast<float>(rgb[c]) - mean));
  }
  const float mean_u = cell.at[0] / 255.0F, mean_v = cell.at[1] / 255.0F;
  cell.at = {fraction255(mean_u + share * (at_u - mean_u)),
             fraction255(mean_v + share * (at_v - mean_v))};
}

std::optional<Eigen::Vector3f> ColourSamples::colourAt(float u, float v) const {
  const int cu = static_cast<int>(std::floor(u * inverse_cell_));
  const int cv = static_cast<int>(std::floor(v * inverse_cell_));
  const auto it = tiles_.find(keyOf(cu >> kTileShift, cv >> kTileShift));
  if (it == tiles_.end()) return std::nullopt;
  const Cell& cell =
      it->second[static_cast<std::size_t>((cv & kCellMask) * kTileCells + (cu & kCellMask))];
  if (cell.weight <= 0.0F) return std::nullopt;
  return Eigen::Vector3f(cell.rgb[0], cell.rgb[1], cell.rgb[2]) / 256.0F;
}

std::size_t ColourSamples::bytes() const {
  return tiles_.size() * static_cast<std::size_t>(kTileCells * kTileCells) * sizeof(Cell);
}

std::vector<ColourSample> ColourSamples::all() const {
  std::vector<ColourSample> samples;
  samples.reserve(size_);
  for (const auto& [key, tile] : tiles_) {
    const auto tile_u = static_cast<int>(key >> 32);
    const auto tile_v = static_cast<int>(static_cast<std::int32_t>(key & 0xffffffff));
    for (int r = 0; r < kTileCells; ++r) {
      for (int c = 0; c < kTileCells; ++c) {
        const Cell& cell = tile[static_cast<std::size_t>(r * kTileCells + c)];
        if (cell.weight <= 0.0F) continue;
        ColourSample sample;
        sample.u = (static_cast<float>(tile_u * kTileCells + c) + cell.at[0] / 255.0F) * cell_m_;
        sample.v = (static_cast<float>(tile_v * kTileCells + r) + cell.at[1] / 255.0F) * cell_m_;
        for (int ch = 0; ch < 3; ++ch) {
          sample.rgb[static_cast<std::size_t>(ch)] =
              static_cast<std::uint8_t>(std::clamp(std::lround(cell.rgb[ch] / 256.0F), 0L, 255L));
        }
        sample.score = std::log(cell.weight);
        samples.push_back(sample);
      }
    }
  }
  return samples;
}

namespace {

constexpr char kSamplesMagic[8] = {'t', 's', 's', 'm', 'p', 'l', 's', '1'};

}  // namespace

void ColourSamples::save(const std::filesystem::path& path) const {
  std::ofstream out(path, std::ios::binary);
  // Tiles in key order, so that the file (and a reload) does not depend on hash order.
  std::vector<std::int64_t> keys;
  for (const auto& entry : tiles_) keys.push_back(entry.first);
  std::sort(keys.begin(), keys.end());
  const std::uint64_t count = keys.size(), size = size_;
  out.write(kSamplesMagic, sizeof kSamplesMagic);
  out.write(reinterpret_cast<const char*>(&cell_m_), sizeof cell_m_);
  out.write(reinterpret_cast<const char*>(&inverse_cell_), sizeof inverse_cell_);
  out.write(reinterpret_cast<const char*>(&size), sizeof size);
  out.write(reinterpret_cast<const char*>(&count), sizeof count);
  for (const std::int64_t key : keys) {
    const std::vector<Cell>& tile = tiles_.at(key);
    out.write(reinterpret_cast<const char*>(&key), sizeof key);
    out.write(reinterpret_cast<const char*>(tile.data()),
              static_cast<std::streamsize>(tile.size() * sizeof(Cell)));
  }
  out.close();
  if (!out) {
    throw core::Error(
        fmt::format("{}: could not write colour samples (disk full?)", path.string()));
  }
}

ColourSamples ColourSamples::load(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  char magic[sizeof kSamplesMagic] = {};
  float cell_m = 0.0F, inverse_cell = 0.0F;
  std::uint64_t size = 0, count = 0;
  in.read(magic, sizeof magic);
  in.read(reinterpret_cast<char*>(&cell_m), sizeof cell_m);
  in.read(reinterpret_cast<char*>(&inverse_cell), sizeof inverse_cell);
  in.read(reinterpret_cast<char*>(&size), sizeof size);
  in.read(reinterpret_cast<char*>(&count), sizeof count);
  if (!in || !std::equal(magic, magic + sizeof magic, kSamplesMagic) || !(cell_m > 0.0F)) {
    throw core::Error(fmt::format("{}: not a colour sample file, or cut short", path.string()));
  }
  ColourSamples samples(cell_m);
  samples.inverse_cell_ = inverse_cell;  // as saved, bit for bit
  for (std::uint64_t i = 0; i < count; ++i) {
    std::int64_t key = 0;
    std::vector<Cell> tile(static_cast<std::size_t>(kTileCells * kTileCells));
    in.read(reinterpret_cast<char*>(&key), sizeof key);
    in.read(reinterpret_cast<char*>(tile.data()),
            static_cast<std::streamsize>(tile.size() * sizeof(Cell)));
    if (!in) throw core::Error(fmt::format("{}: colour samples cut short", path.string()));
    samples.tiles_.emplace(key, std::move(tile));
  }
  samples.size_ = size;
  return samples;
}

}  // namespace tessera::planes
