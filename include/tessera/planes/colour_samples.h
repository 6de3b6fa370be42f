#pragma once
// Colour samples of one patch, taken from the raw frames, with bounded memory per square metre.
// The plane is cut into small cells, grouped in tiles of 32 x 32 cells; a cell blends the
// pixels that fall into it (a running weighted mean of colour and position). With
// views_per_tile 0 (the default) every view blends into one layer of cells. With N > 0 a tile
// keeps the cells of its N heaviest views apart, one layer per view (frame), for the bitmap
// builder to align and choose views per region (docs/MEASUREMENTS.md, "View selection").
#include <array>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <limits>
#include <memory>
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
  std::int32_t view = -1;  // the frame the sample came from; -1 where views are blended
};

class ColourSamples {
 private:
  // 12 bytes a cell: at 3.5 mm cells a fully covered square metre holds 0.98 MB.
  struct Cell {
    float weight = 0.0F;                 // sum of the blended samples' weights; 0: empty
    std::array<std::uint16_t, 3> rgb{};  // running weighted mean, 8.8 fixed point
    std::array<std::uint8_t, 2> at{};    // weighted mean position in the cell, 1/255 of a side
  };
  static constexpr int kTileCells = 32;  // tiles of 32 x 32 cells are allocated as touched
  // One view's cells in a tile.
  struct Layer {
    std::int32_t view = -1;
    float weight = 0.0F;      // summed weight of the view's pixels in the tile
    std::size_t filled = 0;   // cells holding colour
    std::vector<Cell> cells;  // kTileCells x kTileCells
  };
  using Tile = std::vector<Layer>;

 public:
  // views_per_tile: how many views each tile keeps (the heaviest by summed weight); 0 blends
  // all views into one.
  explicit ColourSamples(double cell_m, int views_per_tile = 0);
  ColourSamples(const ColourSamples& other) { *this = other; }
  ColourSamples& operator=(const ColourSamples& other);
  ColourSamples(ColourSamples&& other) noexcept { *this = std::move(other); }
  ColourSamples& operator=(ColourSamples&& other) noexcept;

  // Blends the sample into its cell of its view's layer with weight exp(sample.score).
  void add(const ColourSample& sample);
  // The same with the weight itself (positive), as the per-pixel path has it.
  void add(float u, float v, const std::array<std::uint8_t, 3>& rgb, float weight,
           std::int32_t view = -1);
  // The two halves of add(): where a sample goes (its cell, the tile and layer made if new;
  // the cell's memory is fetched meanwhile), then the blend. A caller with many samples finds
  // the cells of the next ones before blending this one's, so that it does not wait on memory
  // for each. A slot belongs to the object that located it and stays valid until settle()
  // or until that object is moved or assigned; each cell must see its blends in the order
  // add() would have made them.
  struct Slot {
    Tile* tile = nullptr;
    std::uint32_t layer = 0, cell = 0;
    float at_u = 0.0F, at_v = 0.0F;  // the sample's position in its cell, in sides
  };
  Slot locate(float u, float v, std::int32_t view = -1);
  void blend(const Slot& slot, const std::array<std::uint8_t, 3>& rgb, float weight);
  // Drops, in each tile that got more than views_per_tile views since the last call, the
  // layers of least summed weight. Call after adding a view (or a merge's samples): a view's
  // weight in a tile is known only once all its pixels are in.
  void settle();
  // The colour (RGB, 0-255) of the cell holding (u, v) in the heaviest layer that has it.
  std::optional<Eigen::Vector3f> colourAt(float u, float v) const;

  std::size_t size() const { return size_; }  // cells holding colour, over all layers
  std::size_t bytes() const;
  // One sample per cell and layer holding colour: its blended colour at the weighted mean
  // position, with the layer's view.
  std::vector<ColourSample> all() const;

  // The cells as a file, exactly (a finalized patch's samples leave memory so); throws
  // core::Error naming the file when it cannot be written or read back.
  void save(const std::filesystem::path& path) const;
  static ColourSamples load(const std::filesystem::path& path);

 private:
  static std::int64_t keyOf(int tile_u, int tile_v);
  Tile& tileAt(int tile_u, int tile_v);
  Layer& layerOf(Tile& tile, std::int64_t key, std::int32_t view);

  float cell_m_;
  float inverse_cell_;  // 1 / the cell's side, metres
  int views_per_tile_ = 0;
  std::unordered_map<std::int64_t, Tile> tiles_;
  std::size_t size_ = 0;
  std::size_t layers_ = 0;  // over all tiles: bytes() is read every frame for every patch
  std::vector<std::int64_t> crowded_;  // tiles holding more than views_per_tile_ layers
  // Neighbouring pixels mostly land in the same tile: remember the last one looked up
  // (unordered_map elements keep their address when the map grows).
  std::int64_t last_key_ = 0;
  Tile* last_tile_ = nullptr;
};

// A patch's samples, shared with the copies of the patch that are textured on other threads
// (PatchSnapshot) rather than copied for them: a finalization burst would otherwise hold every
// finalized patch's samples twice. The copies only read; the patch clones the samples before
// it changes them while a copy still holds them (copy on write). One thread owns the holder.
class SharedColourSamples {
 public:
  explicit SharedColourSamples(ColourSamples samples)
      : samples_(std::make_shared<ColourSamples>(std::move(samples))) {}
  // Copies share (the next edit() clones); a move copies too, so that no holder is ever left
  // without samples.
  SharedColourSamples(const SharedColourSamples&) = default;
  SharedColourSamples& operator=(const SharedColourSamples&) = default;
  SharedColourSamples& operator=(ColourSamples samples) {
    samples_ = std::make_shared<ColourSamples>(std::move(samples));
    return *this;
  }

  const ColourSamples& operator*() const { return *samples_; }
  const ColourSamples* operator->() const { return samples_.get(); }
  // The samples to change: cloned first while another holder reads them.
  ColourSamples& edit();
  // A read-only handle for another thread; the samples it sees never change.
  std::shared_ptr<const ColourSamples> share() const { return samples_; }

 private:
  std::shared_ptr<ColourSamples> samples_;
};

}  // namespace tessera::planes
