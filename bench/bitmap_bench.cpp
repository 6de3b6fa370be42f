// Bitmap building time per square metre of patch, on one core: a synthetic patch coloured as
// the plane stage colours one (two samples in every 5 mm cell, at random places in it), built
// at a given texel size with the default settings, best view, and fewer neighbours.
//
//   bitmap_bench [--side-m S] [--texel-m T] [--repeats N]
#include <algorithm>
#include <chrono>
#include <random>

#include <fmt/format.h>
#include <CLI/CLI.hpp>
#include <opencv2/core/utility.hpp>

#include "tessera/texture/bitmap_builder.h"

namespace {

tessera::planes::PatchSnapshot syntheticPatch(double side_m, std::uint32_t seed) {
  tessera::planes::PatchSnapshot patch;
  patch.outline.parts.push_back({{{0, 0}, {side_m, 0}, {side_m, side_m}, {0, side_m}}, {}});
  std::mt19937 random(seed);
  std::uniform_real_distribution<float> unit(0.0F, 1.0F);
  std::uniform_int_distribution<int> level(0, 255);
  const double cell = 0.005;
  const int cells = static_cast<int>(side_m / cell);
  for (int i = 0; i < cells; ++i) {
    for (int j = 0; j < cells; ++j) {
      for (int k = 0; k < 2; ++k) {
        tessera::planes::ColourSample s;
        s.u = (static_cast<float>(i) + unit(random)) * static_cast<float>(cell);
        s.v = (static_cast<float>(j) + unit(random)) * static_cast<float>(cell);
        s.rgb = {static_cast<std::uint8_t>(level(random)), static_cast<std::uint8_t>(level(random)),
                 static_cast<std::uint8_t>(level(random))};
        s.score = -unit(random);
        patch.samples.push_back(s);
      }
    }
  }
  return patch;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Bitmap building time per square metre of patch, one core"};
  double side_m = 2.0, texel_m = 0.005;
  int repeats = 3;
  app.add_option("--side-m", side_m, "Side of the square synthetic patch, metres")
      ->check(CLI::PositiveNumber);
  app.add_option("--texel-m", texel_m, "Texel size, metres")->check(CLI::PositiveNumber);
  app.add_option("--repeats", repeats, "Builds per setting (the fastest counts)")
      ->check(CLI::PositiveNumber);
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
  return 0;
}
