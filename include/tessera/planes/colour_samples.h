#pragma once
// Colour samples of one patch, taken from the raw frames, with bounded memory per square metre:
// the plane is cut into small cells and each cell keeps only its best-weighted few samples.
#include <array>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <unordered_map>
#include <utility>
#include <vector>

namespace tessera::planes {

struct ColourSample {
  static constexpr float kEmpty = std::numeric_limits<float>::lowest();
  float u = 0.0F, v = 0.0F;  // position in the patch's plane frame, metres
  std::array<std::uint8_t, 3> rgb{};
  // Natural log of the sample's weight (how close, frontal, sharp and recent its view was):
  // a log, so that a weight growing with the frame index for recency never overflows, and two
  // samples' weights compare as exp(score_a - score_b). kEmpty marks an empty slot.
  float score = kEmpty;
};

class ColourSamples {
 public:
  // At most `per_cell` samples in each `cell_m` x `cell_m` cell of the plane.
  ColourSamples(double cell_m, int per_cell);
  ColourSamples(const ColourSamples& other) { *this = other; }
  ColourSamples& operator=(const ColourSamples& other);
  ColourSamples(ColourSamples&& other) noexcept { *this = std::move(other); }
  ColourSamples& operator=(ColourSamples&& other) noexcept;

  // Keeps the sample if its cell has a free slot or a lower-scored sample, which it replaces.
  void add(const ColourSample& sample);

  std::size_t size() const { return size_; }
  std::size_t bytes() const;
  std::vector<ColourSample> all() const;

 private:
  static constexpr int kTileCells = 32;  // tiles of 32 x 32 cells are allocated as touched
  std::vector<ColourSample>& tileAt(int tile_u, int tile_v);

  float inverse_cell_;  // 1 / the cell's side, metres
  int per_cell_;
  std::unordered_map<std::int64_t, std::vector<ColourSample>> tiles_;
  std::size_t size_ = 0;
  // Neighbouring pixels mostly land in the same tile: remember the last one looked up
  // (unordered_map elements keep their address when the map grows).
  std::int64_t last_key_ = 0;
  std::vector<ColourSample>* last_tile_ = nullptr;
};

}  // namespace tessera::planes
