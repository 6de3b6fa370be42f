#include "tessera/eval/reuse_cost.h"

#include <algorithm>
#include <map>
#include <optional>
#include <regex>
#include <string>
#include <utility>
#include <vector>

namespace tessera::eval {

namespace {

// How a patch's instance stores it other than as its own bitmap; empty when it does not.
std::string storedHow(const nlohmann::json& instance) {
  if (!instance.is_object()) return {};
  std::vector<std::string> ways;
  if (instance.value("reused", false)) ways.emplace_back("reuse");
  if (instance.value("tiled", false)) ways.emplace_back("pattern");
  if (const auto overlays = instance.find("overlays");
      overlays != instance.end() && overlays->is_array() && !overlays->empty()) {
    ways.emplace_back("layers");
  }
  std::string how;
  for (const std::string& way : ways) how += (how.empty() ? "" : "+") + way;
  return how;
}

// The patch a surface of the map draws: (id, version) from "patch_ID_vV[_overlay_K]".
std::optional<std::pair<long, long>> patchOf(const std::string& surface) {
  static const std::regex name(R"(patch_(\d+)_v(\d+)(_overlay_\d+)?)");
  std::smatch match;
  if (!std::regex_match(surface, match, name)) return std::nullopt;
  return std::make_pair(std::stol(match[1]), std::stol(match[2]));
}

nlohmann::json lost(std::optional<double> unmatched, std::optional<double> run) {
  return unmatched && run ? nlohmann::json(*unmatched - *run) : nlohmann::json(nullptr);
}

}  // namespace

nlohmann::json reuseCostFigures(const ViewEvaluation& evaluation, std::size_t unmatched,
                                const nlohmann::json& patches) {
  nlohmann::json figures;
  figures["view_psnr_lost_db"] =
      lost(evaluation.meanPsnr(unmatched, false), evaluation.meanPsnr(0, false));
  figures["view_psnr_lost_holdout_db"] =
      lost(evaluation.meanPsnr(unmatched, true), evaluation.meanPsnr(0, true));
  figures["view_ssim_lost"] = lost(evaluation.mean(unmatched, false, &ImageSimilarity::ssim),
                                   evaluation.mean(0, false, &ImageSimilarity::ssim));
  figures["view_detail_lost"] = lost(evaluation.mean(unmatched, false, &ImageSimilarity::detail),
                                     evaluation.mean(0, false, &ImageSimilarity::detail));

  // Each patch's pixels and squared errors (the run's, then the unmatched run's), its
  // overlays' surfaces with it.
  std::map<std::pair<long, long>, SurfaceError> by_patch;
  for (const SurfaceError& surface : evaluation.surfaces) {
    const auto patch = patchOf(surface.name);
    if (!patch || surface.pixels == 0) continue;
    SurfaceError& sums =
        by_patch.try_emplace(*patch, SurfaceError{surface.name, 0, {0.0, 0.0}}).first->second;
    sums.pixels += surface.pixels;
    sums.squared_error[0] += surface.squared_error.at(0);
    sums.squared_error[1] += surface.squared_error.at(unmatched);
  }
  std::vector<nlohmann::json> costs;
  const auto listed = patches.find("patches");
  for (const nlohmann::json& patch : listed != patches.end() ? *listed : nlohmann::json::array()) {
    const std::string how = storedHow(patch.value("instance", nlohmann::json()));
    if (how.empty()) continue;
    const auto key = std::make_pair(patch.value("id", -1L), patch.value("version", -1L));
    const auto sums = by_patch.find(key);
    if (sums == by_patch.end()) continue;  // not in the training views' compared pixels
    const double psnr = *sums->second.psnr(0), unmatched_psnr = *sums->second.psnr(1);
    costs.push_back({{"patch", key.first},
                     {"version", key.second},
                     {"stored_as", how},
                     {"texture_id", patch["instance"].value("texture_id", -1L)},
                     {"pixels", sums->second.pixels},
                     {"psnr_db", psnr},
                     {"unmatched_psnr_db", unmatched_psnr},
                     {"psnr_lost_db", unmatched_psnr - psnr}});
  }
  std::sort(costs.begin(), costs.end(), [](const nlohmann::json& a, const nlohmann::json& b) {
    return a["psnr_lost_db"].get<double>() > b["psnr_lost_db"].get<double>();
  });
  figures["view_reuse_costs"] = costs;
  return figures;
}

}  // namespace tessera::eval
