#include "tessera/planes/colour_samples.h"

#include <algorithm>
#include <atomic>
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

ColourSamples::ColourSamples(double cell_m, int views_per_tile)
    : cell_m_(static_cast<float>(cell_m)),
      inverse_cell_(static_cast<float>(1.0 / cell_m)),
      views_per_tile_(std::max(views_per_tile, 0)) {}

ColourSamples& ColourSamples::operator=(const ColourSamples& other) {
  cell_m_ = other.cell_m_;
  inverse_cell_ = other.inverse_cell_;
  views_per_tile_ = other.views_per_tile_;
  tiles_ = other.tiles_;
  size_ = other.size_;
  layers_ = other.layers_;
  crowded_ = other.crowded_;
  last_tile_ = nullptr;  // it pointed into the other object's tiles
  return *this;
}

ColourSamples& ColourSamples::operator=(ColourSamples&& other) noexcept {
  cell_m_ = other.cell_m_;
  inverse_cell_ = other.inverse_cell_;
  views_per_tile_ = other.views_per_tile_;
  tiles_ = std::move(other.tiles_);
  size_ = other.size_;
  layers_ = other.layers_;
  crowded_ = std::move(other.crowded_);
  last_tile_ = nullptr;
  other.tiles_.clear();
  other.crowded_.clear();
  other.size_ = 0;
  other.layers_ = 0;
  other.last_tile_ = nullptr;
  return *this;
}

std::int64_t ColourSamples::keyOf(int tile_u, int tile_v) {
  return (static_cast<std::int64_t>(tile_u) << 32) ^ static_cast<std::uint32_t>(tile_v);
}

ColourSamples::Tile& ColourSamples::tileAt(int tile_u, int tile_v) {
  const std::int64_t key = keyOf(tile_u, tile_v);
  if (last_tile_ != nullptr && key == last_key_) return *last_tile_;
  Tile& tile = tiles_[key];
  last_key_ = key;
  last_tile_ = &tile;
  return tile;
}

ColourSamples::Layer& ColourSamples::layerOf(Tile& tile, std::int64_t key, std::int32_t view) {
  if (views_per_tile_ == 0) view = -1;  // one blended layer
  // The view being added is nearly always the newest layer.
  for (auto it = tile.rbegin(); it != tile.rend(); ++it) {
    if (it->view == view) return *it;
  }
  Layer& layer = tile.emplace_back();
  ++layers_;
  layer.view = view;
  layer.cells.resize(static_cast<std::size_t>(kTileCells * kTileCells));
  if (views_per_tile_ > 0 && tile.size() == static_cast<std::size_t>(views_per_tile_) + 1) {
    crowded_.push_back(key);
  }
  return layer;
}

void ColourSamples::settle() {
  for (const std::int64_t key : crowded_) {
    Tile& tile = tiles_.at(key);
    while (tile.size() > static_cast<std::size_t>(views_per_tile_)) {
      const auto lightest =
          std::min_element(tile.begin(), tile.end(),
                           [](const Layer& a, const Layer& b) { return a.weight < b.weight; });
      size_ -= lightest->filled;
      tile.erase(lightest);
      --layers_;
    }
  }
  crowded_.clear();
}

void ColourSamples::add(const ColourSample& sample) {
  // Weights stay within float range whatever the score (a merge passes summed weights).
  add(sample.u, sample.v, sample.rgb, std::exp(std::clamp(sample.score, -60.0F, 60.0F)),
      sample.view);
}

void ColourSamples::add(float u, float v, const std::array<std::uint8_t, 3>& rgb, float weight,
                        std::int32_t view) {
  blend(locate(u, v, view), rgb, weight);
}

ColourSamples::Slot ColourSamples::locate(float u, float v, std::int32_t view) {
  const float cell_u = u * inverse_cell_, cell_v = v * inverse_cell_;
  const int cu = static_cast<int>(std::floor(cell_u));
  const int cv = static_cast<int>(std::floor(cell_v));
  static_assert(kTileCells == 1 << kTileShift);
  Tile& tile = tileAt(cu >> kTileShift, cv >> kTileShift);
  Layer& layer = layerOf(tile, last_key_, view);
  Slot slot;
  slot.tile = &tile;
  slot.layer = static_cast<std::uint32_t>(&layer - tile.data());
  slot.cell = static_cast<std::uint32_t>((cv & kCellMask) * kTileCells + (cu & kCellMask));
  slot.at_u = cell_u - static_cast<float>(cu);
  slot.at_v = cell_v - static_cast<float>(cv);
  __builtin_prefetch(&layer.cells[slot.cell], 1);
  return slot;
}

void ColourSamples::blend(const Slot& slot, const std::array<std::uint8_t, 3>& rgb, float weight) {
  Layer& layer = (*slot.tile)[slot.layer];
  layer.weight += weight;
  Cell& cell = layer.cells[slot.cell];
  if (cell.weight <= 0.0F) {
    ++size_;
    ++layer.filled;
    cell.weight = weight;
    for (int c = 0; c < 3; ++c) cell.rgb[c] = fixed88(rgb[c]);
    cell.at = {fraction255(slot.at_u), fraction255(slot.at_v)};
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
  cell.at = {fraction255(mean_u + share * (slot.at_u - mean_u)),
             fraction255(mean_v + share * (slot.at_v - mean_v))};
}

std::optional<Eigen::Vector3f> ColourSamples::colourAt(float u, float v) const {
  const int cu = static_cast<int>(std::floor(u * inverse_cell_));
  const int cv = static_cast<int>(std::floor(v * inverse_cell_));
  const auto it = tiles_.find(keyOf(cu >> kTileShift, cv >> kTileShift));
  if (it == tiles_.end()) return std::nullopt;
  const auto index = static_cast<std::size_t>((cv & kCellMask) * kTileCells + (cu & kCellMask));
  const Cell* heaviest = nullptr;
  float heaviest_weight = 0.0F;
  for (const Layer& layer : it->second) {
    if (layer.cells[index].weight > 0.0F && layer.weight > heaviest_weight) {
      heaviest = &layer.cells[index];
      heaviest_weight = layer.weight;
    }
  }
  if (heaviest == nullptr) return std::nullopt;
  return Eigen::Vector3f(heaviest->rgb[0], heaviest->rgb[1], heaviest->rgb[2]) / 256.0F;
}

std::size_t ColourSamples::bytes() const {
  return layers_ * static_cast<std::size_t>(kTileCells * kTileCells) * sizeof(Cell);
}

std::vector<ColourSample> ColourSamples::all() const {
  std::vector<ColourSample> samples;
  samples.reserve(size_);
  for (const auto& [key, tile] : tiles_) {
    const auto tile_u = static_cast<int>(key >> 32);
    const auto tile_v = static_cast<int>(static_cast<std::int32_t>(key & 0xffffffff));
    for (const Layer& layer : tile) {
      for (int r = 0; r < kTileCells; ++r) {
        for (int c = 0; c < kTileCells; ++c) {
          const Cell& cell = layer.cells[static_cast<std::size_t>(r * kTileCells + c)];
          if (cell.weight <= 0.0F) continue;
          ColourSample sample;
          sample.u = (static_cast<float>(tile_u * kTileCells + c) + cell.at[0] / 255.0F) * cell_m_;
          sample.v = (static_cast<float>(tile_v * kTileCells + r) + cell.at[1] / 255.0F) * cell_m_;
          for (int ch = 0; ch < 3; ++ch) {
            sample.rgb[static_cast<std::size_t>(ch)] =
                static_cast<std::uint8_t>(std::clamp(std::lround(cell.rgb[ch] / 256.0F), 0L, 255L));
          }
          sample.score = std::log(cell.weight);
          sample.view = layer.view;
          samples.push_back(sample);
        }
      }
    }
  }
  return samples;
}

namespace {

constexpr char kSamplesMagic[8] = {'t', 's', 's', 'm', 'p', 'l', 's', '2'};

}  // namespace

void ColourSamples::save(const std::filesystem::path& path) const {
  // A new file, not the old one rewritten: a saved map may hold a second name for the old one.
  std::error_code ignored;
  if (std::filesystem::is_regular_file(path, ignored)) std::filesystem::remove(path, ignored);
  std::ofstream out(path, std::ios::binary);
  // Tiles in key order, so that the file (and a reload) does not depend on hash order.
  std::vector<std::int64_t> keys;
  for (const auto& entry : tiles_) keys.push_back(entry.first);
  std::sort(keys.begin(), keys.end());
  const std::uint64_t count = keys.size(), size = size_;
  const auto views = static_cast<std::int32_t>(views_per_tile_);
  out.write(kSamplesMagic, sizeof kSamplesMagic);
  out.write(reinterpret_cast<const char*>(&cell_m_), sizeof cell_m_);
  out.write(reinterpret_cast<const char*>(&inverse_cell_), sizeof inverse_cell_);
  out.write(reinterpret_cast<const char*>(&views), sizeof views);
  out.write(reinterpret_cast<const char*>(&size), sizeof size);
  out.write(reinterpret_cast<const char*>(&count), sizeof count);
  for (const std::int64_t key : keys) {
    const Tile& tile = tiles_.at(key);
    const std::uint64_t layers = tile.size();
    out.write(reinterpret_cast<const char*>(&key), sizeof key);
    out.write(reinterpret_cast<const char*>(&layers), sizeof layers);
    for (const Layer& layer : tile) {
      const std::uint64_t filled = layer.filled;
      out.write(reinterpret_cast<const char*>(&layer.view), sizeof layer.view);
      out.write(reinterpret_cast<const char*>(&layer.weight), sizeof layer.weight);
      out.write(reinterpret_cast<const char*>(&filled), sizeof filled);
      out.write(reinterpret_cast<const char*>(layer.cells.data()),
                static_cast<std::streamsize>(layer.cells.size() * sizeof(Cell)));
    }
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
  std::int32_t views = 0;
  std::uint64_t size = 0, count = 0;
  in.read(magic, sizeof magic);
  in.read(reinterpret_cast<char*>(&cell_m), sizeof cell_m);
  in.read(reinterpret_cast<char*>(&inverse_cell), sizeof inverse_cell);
  in.read(reinterpret_cast<char*>(&views), sizeof views);
  in.read(reinterpret_cast<char*>(&size), sizeof size);
  in.read(reinterpret_cast<char*>(&count), sizeof count);
  if (!in || !std::equal(magic, magic + sizeof magic, kSamplesMagic) || !(cell_m > 0.0F)) {
    throw core::Error(fmt::format("{}: not a colour sample file, or cut short", path.string()));
  }
  ColourSamples samples(cell_m, views);
  samples.inverse_cell_ = inverse_cell;  // as saved, bit for bit
  const auto cut_short = [&] {
    return core::Error(fmt::format("{}: colour samples cut short", path.string()));
  };
  for (std::uint64_t i = 0; i < count; ++i) {
    std::int64_t key = 0;
    std::uint64_t layers = 0;
    in.read(reinterpret_cast<char*>(&key), sizeof key);
    in.read(reinterpret_cast<char*>(&layers), sizeof layers);
    if (!in || layers > static_cast<std::uint64_t>(std::max(views, 1)) + 1) throw cut_short();
    Tile& tile = samples.tiles_[key];
    for (std::uint64_t l = 0; l < layers; ++l) {
      Layer& layer = tile.emplace_back();
      ++samples.layers_;
      std::uint64_t filled = 0;
      layer.cells.resize(static_cast<std::size_t>(kTileCells * kTileCells));
      in.read(reinterpret_cast<char*>(&layer.view), sizeof layer.view);
      in.read(reinterpret_cast<char*>(&layer.weight), sizeof layer.weight);
      in.read(reinterpret_cast<char*>(&filled), sizeof filled);
      in.read(reinterpret_cast<char*>(layer.cells.data()),
              static_cast<std::streamsize>(layer.cells.size() * sizeof(Cell)));
      if (!in) throw cut_short();
      layer.filled = static_cast<std::size_t>(filled);
    }
  }
  samples.size_ = size;
  return samples;
}

ColourSamples& SharedColourSamples::edit() {
  if (samples_.use_count() > 1) {
    samples_ = std::make_shared<ColourSamples>(*samples_);
  } else {
    // The last other holder let go: its reads happen before our writes (the count's release
    // decrement, read here, is paired with this fence).
    std::atomic_thread_fence(std::memory_order_acquire);
  }
  return *samples_;
}

}  // namespace tessera::planes
