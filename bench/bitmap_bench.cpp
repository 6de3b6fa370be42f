// Bitmap building time per square metre of patch, on one core: a synthetic patch coloured as
// the plane stage colours one (one blended sample in every 3.5 mm cell, somewhere in it), built
// at a given texel size with the default settings, best view, and fewer neighbours.
//
// With --run OUT (a tessera run's output folder), it also compares, for each finalized patch of
// patches.json, the texel counts of the three ways to lay the grid over its outline.
//
//   bitmap_bench [--side-m S] [--texel-m T] [--repeats N] [--run OUT]
#include <algorithm>
#include <chrono>
#include <random>

#include <fstream>

#include <fmt/format.h>
#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>
#include <opencv2/core/utility.hpp>

#include "tessera/texture/bitmap_builder.h"

namespace {

tessera::planes::PatchSnapshot syntheticPatch(double side_m, std::uint32_t seed) {
  tessera::planes::PatchSnapshot patch;
  patch.outline.parts.push_back({{{0, 0}, {side_m, 0}, {side_m, side_m}, {0, side_m}}, {}});
  std::mt19937 random(seed);
  std::uniform_real_distribution<float> unit(0.0F, 1.0F);
  std::uniform_int_distribution<int> level(0, 255);
  const double cell = tessera::planes::PatchMapConfig{}.sample_cell_m;
  const int cells = static_cast<int>(side_m / cell);
  for (int i = 0; i < cells; ++i) {
    for (int j = 0; j < cells; ++j) {
      tessera::planes::ColourSample s;
      s.u = (static_cast<float>(i) + unit(random)) * static_cast<float>(cell);
      s.v = (static_cast<float>(j) + unit(random)) * static_cast<float>(cell);
      s.rgb = {static_cast<std::uint8_t>(level(random)), static_cast<std::uint8_t>(level(random)),
               static_cast<std::uint8_t>(level(random))};
      s.score = -unit(random);
      patch.samples.push_back(s);
    }
  }
  return patch;
}

tessera::planes::Polygon2 polygonOf(const nlohmann::json& points) {
  tessera::planes::Polygon2 polygon;
  for (const auto& p : points) polygon.emplace_back(p.at(0).get<double>(), p.at(1).get<double>());
  return polygon;
}

// Grid sizes per patch of a run: principal axes (what tessera uses), axis-aligned in the
// patch's (u, v) frame, and the minimum-area rectangle.
void compareGridsOfRun(const std::string& run_dir, double texel_m) {
  std::ifstream in(run_dir + "/patches.json");
  if (!in) {
    fmt::print(stderr, "{}/patches.json: cannot open\n", run_dir);
    return;
  }
  const auto patches = nlohmann::json::parse(in);
  fmt::print("\ngrid texels at {:.1f} mm: patch, principal axes, axis-aligned, minimum-area\n",
             texel_m * 1000);
  std::size_t principal = 0, aligned = 0, minimum = 0;
  for (const auto& patch : patches.at("patches")) {
    tessera::planes::Outline outline;
    for (const auto& part : patch.at("outline")) {
      tessera::planes::OutlinePart outline_part{polygonOf(part.at("outer")), {}};
      for (const auto& hole : part.at("holes")) outline_part.holes.push_back(polygonOf(hole));
      outline.parts.push_back(outline_part);
    }
    const auto sizes = tessera::texture::compareGrids(outline, texel_m);
    fmt::print("  {:>3} {:>10} {:>10} {:>10}\n", patch.at("id").get<int>(), sizes.principal_axes,
               sizes.axis_aligned, sizes.minimum_area);
    principal += sizes.principal_axes, aligned += sizes.axis_aligned, minimum += sizes.minimum_area;
  }
  fmt::print(
      "  all {:>10} {:>10} {:>10}   principal axes save {:.1f} % on axis-aligned, "
      "{:.1f} % on minimum-area\n",
      principal, aligned, minimum,
      100.0 * (1.0 - static_cast<double>(principal) / static_cast<double>(aligned)),
      100.0 * (1.0 - static_cast<double>(principal) / static_cast<double>(minimum)));
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Bitmap building time per square metre of patch, one core"};
  double side_m = 2.0, texel_m = 0.005;
  int repeats = 3;
  std::string run_dir;
  app.add_option("--side-m", side_m, "Side of the square synthetic patch, metres")
      ->check(CLI::PositiveNumber);
  app.add_option("--texel-m", texel_m, "Texel size, metres")->check(CLI::PositiveNumber);
  app.add_option("--repeats", repeats, "Builds per setting (the fastest counts)")
      ->check(CLI::PositiveNumber);
  app.add_option("--run", run_dir, "A tessera run's output folder: compare its patches' grids");
  CLI11_PARSE(app, argc, argv);
  cv::setNumThreads(1);  // one core, as the texturing node gives each patch

  const tessera::planes::PatchSnapshot patch = syntheticPatch(side_m, 1);
  const double area_m2 = side_m * side_m;
  fmt::print("patch {:.1f} m x {:.1f} m, {} samples, texel {:.1f} mm\n", side_m, side_m,
             patch.samples.size(), texel_m * 1000);
  struct Setting {
    const char* name;
    tessera::texture::BitmapConfig config;
  };
  tessera::texture::BitmapConfig base;
  base.texel_m = texel_m;
  std::vector<Setting> settings{{"default (8 neighbours, mean)", base}};
  settings.push_back({"best view", base});
  settings.back().config.best_view = true;
  settings.push_back({"4 neighbours", base});
  settings.back().config.neighbours = 4;
  for (const Setting& setting : settings) {
    double best_ms = 1e300;
    std::size_t observed = 0;
    for (int r = 0; r < repeats; ++r) {
      const auto bitmap = tessera::texture::buildBitmap(patch, setting.config);
      best_ms = std::min(best_ms, bitmap.build_ms);
      observed = bitmap.observed;
    }
    fmt::print("{:<30} {:8.1f} ms  {:6.1f} ms/m^2  {:.2f} us/texel\n", setting.name, best_ms,
               best_ms / area_m2, 1000.0 * best_ms / static_cast<double>(observed));
  }
  if (!run_dir.empty()) compareGridsOfRun(run_dir, texel_m);
  return 0;
}
