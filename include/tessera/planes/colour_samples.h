#pragma once
// Colour samples of one patch, taken from the raw frames, with bounded memory per square metre:
// the plane is cut into small cells and each cell blends every sample that falls into it (a
// running weighted mean of colour and position), so a texel averages many views instead of
// keeping the one or two heaviest. On real cameras neighbouring cells kept from different
// frames differ in exposure and white balance; blended cells do not (docs/MEASUREMENTS.md,
// "Textures on real cameras").
#include <array>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <limits>
#include <optional>
#include <unordered_map>
#include <utility>
#include <vector>

#include <Eigen/Core>

namespace tessera::planes {

struct ColourSample {
  static constexpr float kEmpty = std::numeric_limits<float>::lowest();
  float u = 0.0F, v = 0.0F;  // position in the patch's plane frame, metres
  std::array<std::uint8_t, 3> rgb{};
  // Natural log of the sample's weight (how close, frontal and sharp its views were; for a
  // blended cell, of the sum of its samples' weights). A log, so that weights of very
  // different size compare as exp(score_a - score_b).
  float score = kEmpty;
};

class ColourSamples {
 public:
  explicit ColourSamples(double cell_m);
  ColourSamples(const ColourSamples& other) { *this = other; }
  ColourSamples& operator=(const ColourSamples& other);
  ColourSamples(ColourSamples&& other) noexcept { *this = std::move(other); }
  ColourSamples& operator=(ColourSamples&& other) noexcept;

  // Blends the sample into its cell with weight exp(sample.score).
  void add(const ColourSample& sample);
  // The same with the weight itself (positive), as the per-pixel path has it.
  void add(float u, float v, const std::array<std::uint8_t, 3>& rgb, float weight);
  // The blended colour (RGB, 0-255) of the cell holding (u, v), if any sample reached it.
  std::optional<Eigen::Vector3f> colourAt(float u, float v) const;

  std::size_t size() const { return size_; }  // cells holding colour
  std::size_t bytes() const;
  // One sample per cell holding colour: its blended colour at the weighted mean position.
  std::vector<ColourSample> all() const;

  // The cells as a file, exactly (a finalized patch's samples leave memory so); throws
  // core::Error naming the file when it cannot be written or read back.
  void save(const std::filesystem::path& path) const;
  static ColourSamples load(const std::filesystem::path& path);

 private:
  // 12 bytes a cell: at 3.5 mm cells a fully covered square metre holds 0.98 MB.
  struct Cell {
    float weight = 0.0F;                 // sum of the blended samples' weights; 0: empty
    std::array<std::uint16_t, 3> rgb{};  // running weighted mean, 8.8 fixed point
    std::array<std::uint8_t, 2> at{};    // weighted mean position in the cell, 1/255 of a side
  };
  static constexpr int kTileCells = 32;  // tiles of 32 x 32 cells are allocated as touched
  static std::int64_t keyOf(int tile_u, int tile_v);
  std::vector<Cell>& tileAt(int tile_u, int tile_v);

  float cell_m_;
  float inverse_cell_;  // 1 / the cell's side, metres
  std::unordered_map<std::int64_t, std::vector<Cell>> tiles_;
  std::size_t size_ = 0;
  // Neighbouring pixels mostly land in the same tile: remember the last one looked up
  // (unordered_map elements keep their address when the map grows).
  std::int64_t last_key_ = 0;
  std::vector<Cell>* last_tile_ = nullptr;
};

}  // namespace tessera::planes
