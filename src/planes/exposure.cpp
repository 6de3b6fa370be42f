#include "tessera/planes/exposure.h"

#include <algorithm>
#include <cmath>

namespace tessera::planes {

namespace {

constexpr float kDarkest = 8.0F;  // below: noise and black level dominate
// Dark surfaces (a switched-off screen) give ratios of small, noisy numbers and change with
// reflections: pairs need this mean brightness.
constexpr float kDimmest = 48.0F;
constexpr float kBrightest = 247.0F;     // above: the channel may be clipped
constexpr float kMaxRatioSpread = 1.3F;  // kept pairs are within this factor of the median
constexpr float kMinGain = 0.33F, kMaxGain = 3.0F;

bool usable(const Eigen::Vector3f& rgb) {
  return rgb.minCoeff() >= kDarkest && rgb.maxCoeff() <= kBrightest && rgb.mean() >= kDimmest;
}

}  // namespace

std::optional<Eigen::Vector3f> estimateGain(const std::vector<ColourPair>& pairs,
                                            std::size_t min_pairs) {
  std::vector<const ColourPair*> kept;
  std::vector<float> ratios;
  for (const ColourPair& pair : pairs) {
    if (!usable(pair.observed) || !usable(pair.reference)) continue;
    kept.push_back(&pair);
    ratios.push_back(pair.reference.sum() / pair.observed.sum());
  }
  if (kept.size() < min_pairs) return std::nullopt;
  std::vector<float> sorted = ratios;
  const auto middle = sorted.begin() + static_cast<std::ptrdiff_t>(sorted.size() / 2);
  std::nth_element(sorted.begin(), middle, sorted.end());
  const float median = *middle;
  Eigen::Vector3d observed = Eigen::Vector3d::Zero(), reference = Eigen::Vector3d::Zero();
  std::size_t count = 0;
  for (std::size_t i = 0; i < kept.size(); ++i) {
    if (ratios[i] > median * kMaxRatioSpread || ratios[i] * kMaxRatioSpread < median) continue;
    observed += kept[i]->observed.cast<double>();
    reference += kept[i]->reference.cast<double>();
    ++count;
  }
  // A change of exposure moves most pairs alike; ratios scattered so that few agree with the
  // median are misregistration or different surfaces, and say nothing about the gain.
  constexpr double kMinAgreeing = 0.5;
  if (count < min_pairs ||
      static_cast<double>(count) < kMinAgreeing * static_cast<double>(kept.size())) {
    return std::nullopt;
  }
  const Eigen::Vector3d gain = reference.cwiseQuotient(observed);
  return gain.cast<float>().cwiseMax(kMinGain).cwiseMin(kMaxGain);
}

}  // namespace tessera::planes
