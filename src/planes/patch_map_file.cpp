// A patch map saved for a later session to continue (`tessera run --continue`).
#include <algorithm>
#include <filesystem>
#include <limits>
#include <map>
#include <string>
#include <vector>

#include <fmt/format.h>

#include "tessera/core/binary_file.h"
#include "tessera/core/error.h"
#include "tessera/core/output_file.h"
#include "tessera/planes/patch_map.h"

namespace tessera::planes {

namespace {

constexpr char kTag[] = "tessera-patch-map";
constexpr std::uint32_t kFormat = 1;
// Far above any real map: a corrupt count is refused before it is allocated.
constexpr std::size_t kMaxItems = 1U << 28U;
// The fewest bytes a stored plane, tile and patch take (what a count is checked against).
constexpr std::size_t kPlaneBytes = 4 + 18 * 8;
constexpr std::size_t kTileBytes = 3 * 4;
constexpr std::size_t kPatchBytes = 4 * 4 + 8;

std::filesystem::path samplesFile(const std::filesystem::path& dir, int patch_id) {
  return dir / fmt::format("patch_{}.samples", patch_id);
}

void writeVector(core::BinaryWriter& out, const Eigen::Vector3d& v) {
  out.value(v.x());
  out.value(v.y());
  out.value(v.z());
}

Eigen::Vector3d readVector(core::BinaryReader& in) {
  Eigen::Vector3d v;
  v.x() = in.value<double>();
  v.y() = in.value<double>();
  v.z() = in.value<double>();
  return v;
}

void writeCell(core::BinaryWriter& out, const Cell& cell) {
  out.value(cell.first);
  out.value(cell.second);
}

Cell readCell(core::BinaryReader& in) {
  const int u = in.value<int>();
  return {u, in.value<int>()};
}

struct StoredCell {
  int u, v;
};

// The settings a saved map's cells and samples depend on.
struct SavedGrid {
  double cell_m, sample_cell_m, tile_m;
  int sample_views;
};

}  // namespace

void PatchMap::saveState(const std::filesystem::path& file,
                         const std::filesystem::path& samples_dir) const {
  std::filesystem::create_directories(samples_dir);
  core::BinaryWriter out(file, kTag, kFormat);
  out.value(SavedGrid{config_.cell_m, config_.sample_cell_m, config_.tile_m, config_.sample_views});
  out.value(next_id_);
  out.value(next_plane_id_);
  out.value(static_cast<std::uint64_t>(planes_.size()));
  for (const auto& [id, plane] : planes_) {
    out.value(plane.id);
    const PlaneGeometry& g = *plane.geometry;
    writeVector(out, g.normal);
    out.value(g.offset);
    writeVector(out, g.origin);
    writeVector(out, g.u_axis);
    writeVector(out, g.v_axis);
    out.value(plane.moments.count);
    writeVector(out, plane.moments.sum);
    for (int i = 0; i < 9; ++i) out.value(plane.moments.outer(i));
    out.value(plane.grid.tile_cells);
    for (const auto& anchor : plane.grid.anchor) {
      out.value(static_cast<std::uint8_t>(anchor.has_value()));
      out.value(anchor.value_or(0));
    }
    writeCell(out, plane.lo);
    writeCell(out, plane.hi);
    out.value(static_cast<std::uint8_t>(plane.has_cells));
    out.value(static_cast<std::uint64_t>(plane.tiles.size()));
    for (const auto& [key, patch_id] : plane.tiles) {
      writeCell(out, key);
      out.value(patch_id);
    }
  }
  out.value(static_cast<std::uint64_t>(patches_.size()));
  for (const auto& [id, patch] : patches_) {
    out.value(patch.id);
    out.value(patch.plane);
    writeCell(out, patch.tile);
    std::vector<Cell> sorted(patch.cells.begin(), patch.cells.end());
    std::sort(sorted.begin(), sorted.end());  // the file does not depend on hash order
    std::vector<StoredCell> cells;
    cells.reserve(sorted.size());
    for (const Cell& cell : sorted) cells.push_back({cell.first, cell.second});
    out.values(cells);
    out.value(patch.footprint_sum_m);
    out.value(static_cast<std::uint64_t>(patch.footprint_pixels));
    writeVector(out, patch.log_gain_sum);
    out.value(patch.version);
    out.value(static_cast<std::uint8_t>(patch.finalized));
    out.value(patch.finalized_area_m2);
    out.value(patch.frames_seen);
    if (patch.spilled_samples) {
      core::linkOrCopy(*patch.spilled_samples, samplesFile(samples_dir, patch.id));
    } else {
      patch.samples->save(samplesFile(samples_dir, patch.id));
    }
  }
  out.finish();
}

void PatchMap::loadState(const std::filesystem::path& file,
                         const std::filesystem::path& samples_dir) {
  core::BinaryReader in(file, kTag, kFormat);
  const auto grid = in.value<SavedGrid>();
  if (grid.cell_m != config_.cell_m || grid.sample_cell_m != config_.sample_cell_m ||
      grid.tile_m != config_.tile_m || grid.sample_views != config_.sample_views) {
    throw core::Error(fmt::format(
        "{}: saved with patches cell_m {}, sample_cell_m {}, tile_m {}, sample_views {}; this "
        "run's configuration has {}, {}, {}, {}: continue with the earlier configuration",
        file.string(), grid.cell_m, grid.sample_cell_m, grid.tile_m, grid.sample_views,
        config_.cell_m, config_.sample_cell_m, config_.tile_m, config_.sample_views));
  }
  const int next_id = in.value<int>();
  const int next_plane_id = in.value<int>();
  std::map<int, Plane> planes;
  for (std::size_t n = in.count(kMaxItems, kPlaneBytes); n > 0; --n) {
    Plane plane;
    plane.id = in.value<int>();
    PlaneGeometry& g = *plane.geometry;
    g.normal = readVector(in);
    g.offset = in.value<double>();
    g.origin = readVector(in);
    g.u_axis = readVector(in);
    g.v_axis = readVector(in);
    plane.moments.count = in.value<double>();
    plane.moments.sum = readVector(in);
    for (int i = 0; i < 9; ++i) plane.moments.outer(i) = in.value<double>();
    plane.grid.tile_cells = in.value<int>();
    for (auto& anchor : plane.grid.anchor) {
      const bool set = in.value<std::uint8_t>() != 0;
      const int at = in.value<int>();
      if (set) anchor = at;
    }
    plane.lo = readCell(in);
    plane.hi = readCell(in);
    plane.has_cells = in.value<std::uint8_t>() != 0;
    if (plane.grid.tile_cells <= 0) in.corrupt(fmt::format("plane {} has no tile size", plane.id));
    for (std::size_t t = in.count(kMaxItems, kTileBytes); t > 0; --t) {
      const Cell key = readCell(in);
      plane.tiles[key] = in.value<int>();
    }
    const int id = plane.id;
    if (!planes.emplace(id, std::move(plane)).second) in.corrupt("a plane id twice");
  }
  std::map<int, Patch> patches;
  for (std::size_t n = in.count(kMaxItems, kPatchBytes); n > 0; --n) {
    Patch patch;
    patch.samples = ColourSamples(config_.sample_cell_m, config_.sample_views);
    patch.id = in.value<int>();
    patch.plane = in.value<int>();
    patch.tile = readCell(in);
    for (const StoredCell& cell : in.values<StoredCell>(kMaxItems)) {
      patch.cells.emplace(cell.u, cell.v);
    }
    patch.footprint_sum_m = in.value<double>();
    patch.footprint_pixels = static_cast<std::size_t>(in.value<std::uint64_t>());
    patch.log_gain_sum = readVector(in);
    patch.version = in.value<int>();
    patch.finalized = in.value<std::uint8_t>() != 0;
    patch.finalized_area_m2 = in.value<double>();
    patch.frames_seen = in.value<int>();
    const auto plane = planes.find(patch.plane);
    if (plane == planes.end()) in.corrupt(fmt::format("patch {} on no plane", patch.id));
    patch.geometry = plane->second.geometry;
    const std::filesystem::path samples = samplesFile(samples_dir, patch.id);
    if (!std::filesystem::is_regular_file(samples)) {
      throw core::Error(
          fmt::format("{}: missing (the colour samples of patch {})", samples.string(), patch.id));
    }
    const int id = patch.id;
    if (!patches.emplace(id, std::move(patch)).second) in.corrupt("a patch id twice");
  }
  in.expectEnd();
  for (const auto& [id, plane] : planes) {
    if (id >= next_plane_id) in.corrupt(fmt::format("plane {} not below the next id", id));
    for (const auto& [key, patch_id] : plane.tiles) {
      const auto patch = patches.find(patch_id);
      if (patch == patches.end() || patch->second.plane != id || patch->second.tile != key) {
        in.corrupt(fmt::format("plane {}'s tiles and its patches disagree", id));
      }
    }
  }
  for (const auto& [id, patch] : patches) {
    if (id >= next_id) in.corrupt(fmt::format("patch {} not below the next id", id));
    if (planes.at(patch.plane).tiles.count(patch.tile) == 0) {
      in.corrupt(fmt::format("patch {} is no tile of its plane", id));
    }
  }
  // Only now is the map replaced: a file refused above leaves it as it was.
  if (spill_dir_) std::filesystem::create_directories(*spill_dir_);
  for (auto& [id, patch] : patches) {
    const std::filesystem::path samples = samplesFile(samples_dir, id);
    // A finalized patch's samples stay out of memory until it is seen again, as a spilled
    // patch's do; a growing patch's are used as it grows or is finalized.
    if (spill_dir_ && patch.finalized) {
      const std::filesystem::path spilled = samplesFile(*spill_dir_, id);
      core::linkOrCopy(samples, spilled);
      patch.spilled_samples = spilled;
    } else {
      patch.samples = ColourSamples::load(samples);
    }
  }
  planes_ = std::move(planes);
  patches_ = std::move(patches);
  next_id_ = next_id;
  next_plane_id_ = next_plane_id;
  seen_this_frame_.clear();
  pending_.clear();
  moving_planes_.clear();
}

std::size_t PatchMap::setAsideAll() {
  for (const auto& [id, plane] : planes_) set_aside_.insert(id);
  return planes_.size();
}

void PatchMap::textureAgain(int id) {
  Patch& patch = patchWithId(id);
  if (!patch.finalized) return;
  restoreSamples(patch);
  patch.finalized = false;
  patch.last_seen_frame = std::numeric_limits<long>::min() / 2;  // out of view since long ago
}

}  // namespace tessera::planes
