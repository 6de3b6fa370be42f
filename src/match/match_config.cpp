#include "tessera/match/match_config.h"

#include "tessera/core/error.h"

namespace tessera::match {

void readConfig(const core::ConfigSection& section, MatchConfig& config) {
  section.read("enabled", config.enabled);
  section.read("ccv_blur_sigma_px", config.ccv.blur_sigma_px);
  section.read("ccv_levels", config.ccv.levels);
  section.read("ccv_coherent_fraction", config.ccv.coherent_fraction);
  section.read("ccv_min_coherent_px", config.ccv.min_coherent_px);
  section.read("ccv_normalise_exposure", config.ccv.normalise_exposure);
  section.read("ccv_max_distance", config.ccv_max_distance);
  int max_candidates = static_cast<int>(config.max_candidates);
  section.read("max_candidates", max_candidates);
  section.read("detector", config.features.detector);
  section.read("max_features", config.features.max_features);
  section.read("ratio", config.features.ratio);
  section.read("ransac_threshold_px", config.features.ransac_threshold_px);
  section.read("min_inliers", config.features.min_inliers);
  section.read("min_scale", config.features.min_scale);
  section.read("max_scale", config.features.max_scale);
  section.read("ncc_min_score", config.ncc_min_score);
  section.read("min_psnr_db", config.min_psnr_db);
  section.read("min_coverage", config.min_coverage);
  section.read("describe_max_px", config.describe_max_px);
  section.read("catalog_cache_mb", config.catalog_cache_mb);
  section.read("precheck", config.precheck);
  if (config.catalog_cache_mb < 0.0)
    throw core::ConfigError("match: catalog_cache_mb must be >= 0");
  if (config.ccv.levels < 2 || config.ccv.levels > 16) {
    throw core::ConfigError("match: ccv_levels must be between 2 and 16");
  }
  if (config.ccv.blur_sigma_px < 0.0 || config.ccv.coherent_fraction < 0.0 ||
      config.ccv.min_coherent_px < 1) {
    throw core::ConfigError(
        "match: ccv_blur_sigma_px and ccv_coherent_fraction must be >= 0, ccv_min_coherent_px "
        ">= 1");
  }
  if (max_candidates < 1) throw core::ConfigError("match: max_candidates must be at least 1");
  config.max_candidates = static_cast<std::size_t>(max_candidates);
  if (config.features.detector != "sift" && config.features.detector != "orb" &&
      config.features.detector != "akaze") {
    throw core::ConfigError("match: detector must be sift, orb or akaze");
  }
  if (config.features.ratio <= 0.0 || config.features.ratio >= 1.0 ||
      config.features.min_inliers < 3 || config.features.max_features < 10) {
    throw core::ConfigError(
        "match: ratio must be in (0, 1), min_inliers at least 3, max_features at least 10");
  }
  if (config.features.min_scale <= 0.0 || config.features.max_scale < config.features.min_scale) {
    throw core::ConfigError("match: need 0 < min_scale <= max_scale");
  }
  if (config.min_coverage <= 0.0 || config.min_coverage > 1.0) {
    throw core::ConfigError("match: min_coverage must be in (0, 1]");
  }
}

}  // namespace tessera::match
