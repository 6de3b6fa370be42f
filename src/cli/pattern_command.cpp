#include "pattern_command.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "tessera/core/error.h"
#include "tessera/pattern/pattern_extractor.h"
#include "tessera/pipeline/run_config.h"
#include "texture_image.h"

namespace tessera::cli {

namespace {

nlohmann::json vectorJson(const Eigen::Vector2d& v) { return {v.x(), v.y()}; }

nlohmann::json analysisJson(const pattern::PatternAnalysis& analysis) {
  const auto& found = analysis.pattern;
  nlohmann::json out = {{"verdict", pattern::periodicityName(analysis.verdict())},
                        {"v1", nullptr},
                        {"v2", nullptr},
                        {"tile", nullptr},
                        {"psnr_db", nullptr}};
  if (found) {
    out["v1"] = vectorJson(found->lattice.v1);
    if (found->periodicity == pattern::Periodicity::kTwoDirections) {
      out["v2"] = vectorJson(found->lattice.v2);
    }
    out["tile"] = {found->tile_rgb.cols, found->tile_rgb.rows};
    out["psnr_db"] = found->psnr_db;
    out["explained"] = found->explained;
    out["repeats"] = found->repeats;
    // 0 under even light; else the bitmap is the tiling times a gain field this uneven.
    out["shading_spread"] = found->shading.empty() ? 0.0 : found->shading_spread;
    nlohmann::json overlays = nlohmann::json::array();
    for (const cv::Rect& r : found->overlays) overlays.push_back({r.x, r.y, r.width, r.height});
    out["overlays"] = overlays;
  } else {
    out["reason"] = analysis.reason;
  }
  // What the autocorrelation proposed, before the tiling was judged.
  const pattern::LatticeEstimate& estimate = analysis.estimate;
  out["autocorrelation"] = {{"periodicity", pattern::periodicityName(estimate.periodicity)},
                            {"v1", vectorJson(estimate.lattice.v1)},
                            {"v2", vectorJson(estimate.lattice.v2)},
                            {"score", estimate.score}};
  out["ms"] = analysis.ms;
  return out;
}

}  // namespace

CLI::App* addPatternCommand(CLI::App& app, PatternArguments& args) {
  CLI::App* command = app.add_subcommand(
      "pattern",
      "Look for a periodic pattern in an image: verdict (periodic2, periodic1 or none), "
      "lattice vectors, tile size and the tiling's PSNR");
  command->add_option("IMAGE", args.image, "The image (alpha, if any: valid texels)")
      ->required()
      ->check(CLI::ExistingFile);
  command->add_option("--config", args.config, "YAML config whose pattern: keys to use")
      ->check(CLI::ExistingFile);
  command->add_option("--out", args.out, "Write the tile (one lattice cell) to this PNG");
  command->add_flag("--json", args.json,
                    "Print one JSON object: verdict, v1, v2, tile, psnr_db (vectors in pixels)");
  return command;
}

int patternCommand(const PatternArguments& args) {
  try {
    const pipeline::RunConfig config = pipeline::loadRunConfig(
        args.config.empty() ? std::nullopt : std::optional<std::filesystem::path>(args.config));
    cv::Mat rgb, mask;
    readTextureImage(args.image, rgb, mask);
    const pattern::PatternAnalysis analysis =
        pattern::analysePattern(rgb, mask, config.pattern.extractor);
    const nlohmann::json out = analysisJson(analysis);
    if (args.json) {
      fmt::print("{}\n", out.dump());
    } else if (const auto& found = analysis.pattern) {
      fmt::print("{}: {}\n", args.image, pattern::periodicityName(found->periodicity));
      fmt::print("  v1 ({:.2f}, {:.2f})", found->lattice.v1.x(), found->lattice.v1.y());
      if (found->periodicity == pattern::Periodicity::kTwoDirections) {
        fmt::print("  v2 ({:.2f}, {:.2f})", found->lattice.v2.x(), found->lattice.v2.y());
      }
      fmt::print(
          "\n  tile {}x{}, {:.1f} repeats, tiling PSNR {:.1f} dB, explains {:.0f} % of "
          "the variance, {} overlay(s)\n",
          found->tile_rgb.cols, found->tile_rgb.rows, found->repeats, found->psnr_db,
          100.0 * found->explained, found->overlays.size());
      if (!found->shading.empty()) {
        fmt::print("  under uneven light: tile x shading, the gain spanning {:.0f} % (PSNR and "
                   "variance of the bitmap divided by it)\n",
                   100.0 * found->shading_spread);
      }
    } else {
      fmt::print("{}: none ({})\n", args.image, analysis.reason);
      const pattern::LatticeEstimate& e = analysis.estimate;
      if (e.periodicity != pattern::Periodicity::kNone) {
        fmt::print(
            "  the autocorrelation proposed {} v1 ({:.2f}, {:.2f}) v2 ({:.2f}, {:.2f}), "
            "peak {:.2f}\n",
            pattern::periodicityName(e.periodicity), e.lattice.v1.x(), e.lattice.v1.y(),
            e.lattice.v2.x(), e.lattice.v2.y(), e.score);
      }
    }
    if (!args.out.empty()) {
      if (!analysis.pattern) throw core::Error(fmt::format("{}: no tile to write", args.out));
      cv::Mat bgra;
      cv::cvtColor(analysis.pattern->tile_rgb, bgra, cv::COLOR_RGB2BGRA);
      std::vector<cv::Mat> channels;
      cv::split(bgra, channels);
      channels[3] = analysis.pattern->tile_mask;
      cv::merge(channels, bgra);
      if (!cv::imwrite(args.out, bgra)) {
        throw core::Error(fmt::format("{}: could not be written", args.out));
      }
    }
    return analysis.pattern ? 0 : 3;
  } catch (const core::Error& e) {
    spdlog::error("{}", e.what());
    return 1;
  }
}

}  // namespace tessera::cli
