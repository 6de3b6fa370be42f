#include "match_command.h"

#include <cmath>

#include <fmt/format.h>
#include <spdlog/spdlog.h>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "tessera/core/error.h"
#include "tessera/match/fidelity.h"
#include "tessera/match/match_cascade.h"
#include "tessera/pipeline/run_config.h"
#include "texture_image.h"

namespace tessera::cli {

namespace {

nlohmann::json verdictJson(const match::CandidateVerdict& v) {
  nlohmann::json out = {{"method", v.method},
                        {"accepted", v.accepted},
                        {"psnr_db", v.psnr_db},
                        {"coverage", v.coverage},
                        {"reason", v.reason}};
  if (v.transform) {
    const core::Similarity2& s = *v.transform;
    out["transform"] = {s.a, s.b, s.tx, s.ty};
    out["angle_deg"] = s.angleRad() * 180.0 / M_PI;
    out["scale"] = s.scale();
  }
  return out;
}

}  // namespace

CLI::App* addMatchCommand(CLI::App& app, MatchArguments& args) {
  CLI::App* match = app.add_subcommand(
      "match",
      "Run the matching cascade for image A (a new bitmap) against image B (a stored "
      "texture): CCV distance, transform, PSNR and the verdict");
  match->add_option("A", args.query, "The new bitmap (alpha, if any: valid texels)")
      ->required()
      ->check(CLI::ExistingFile);
  match->add_option("B", args.stored, "The stored texture")->required()->check(CLI::ExistingFile);
  match->add_flag("--pattern", args.pattern, "B is one tile of a repeating pattern");
  match->add_option("--config", args.config, "YAML config whose match: keys to use")
      ->check(CLI::ExistingFile);
  match->add_option("--render", args.render,
                    "Write B rendered through the found transform onto A's grid to this PNG");
  match->add_flag("--json", args.json, "Print one JSON object");
  return match;
}

int matchCommand(const MatchArguments& args) {
  try {
    const pipeline::RunConfig config = pipeline::loadRunConfig(
        args.config.empty() ? std::nullopt : std::optional<std::filesystem::path>(args.config));
    const match::MatchCascade cascade(config.match);
    cv::Mat a_rgb, a_mask, b_rgb, b_mask;
    readTextureImage(args.query, a_rgb, a_mask);
    readTextureImage(args.stored, b_rgb, b_mask);
    const match::TextureDescription query = match::describeTexture(a_rgb, a_mask, config.match);
    std::shared_ptr<match::StoredTexture> stored;
    if (args.pattern) {  // B is one period in each direction
      const core::Lattice2 cell{{b_rgb.cols, 0.0}, {0.0, b_rgb.rows}};
      stored = match::patternTexture(1, b_rgb, b_mask, cell, config.match);
    } else {
      stored = std::make_shared<match::StoredTexture>();
      stored->id = 1;
      stored->description = match::describeTexture(b_rgb, b_mask, config.match);
    }

    const double distance = match::ccvDistance(query.ccv.values, stored->description.ccv.values);
    const bool passes = distance <= config.match.ccv_max_distance;
    // The candidate is verified even when the prefilter would remove it, so that a user sees
    // what each threshold decides.
    const match::CandidateVerdict verdict = cascade.tryCandidate(query, *stored, distance);
    const bool accepted = passes && verdict.accepted;
    nlohmann::json out = {{"ccv_distance", distance},
                          {"ccv_max_distance", config.match.ccv_max_distance},
                          {"ccv_passes", passes},
                          {"keypoints_a", query.features.keypoints.size()},
                          {"keypoints_b", stored->description.features.keypoints.size()},
                          {"verdict", verdictJson(verdict)},
                          {"match", accepted}};
    if (args.json) {
      fmt::print("{}\n", out.dump(2));
    } else {
      fmt::print("CCV distance {:.3f} ({} the prefilter's {:.2f})\n", distance,
                 passes ? "within" : "beyond", config.match.ccv_max_distance);
      fmt::print("{}: {}\n", verdict.method, verdictJson(verdict).dump());
      fmt::print("{}\n", accepted ? "match: A reuses B" : "no match: A is stored on its own");
    }
    if (!args.render.empty() && verdict.transform) {
      const match::Rendered render =
          match::renderStored(*stored, *verdict.transform, a_rgb.cols, a_rgb.rows);
      cv::Mat bgr;
      cv::cvtColor(render.rgb, bgr, cv::COLOR_RGB2BGR);
      if (!cv::imwrite(args.render, bgr)) {
        throw core::Error(fmt::format("{}: could not be written", args.render));
      }
    }
    return accepted ? 0 : 3;
  } catch (const core::Error& e) {
    spdlog::error("{}", e.what());
    return 1;
  }
}

}  // namespace tessera::cli
