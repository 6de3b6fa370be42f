#include "tessera/core/quantiles.h"

#include <algorithm>
#include <cmath>

namespace tessera::core {

namespace {

constexpr double kLowest = 1e-3;  // the first bin's lower edge
constexpr double kHighest = 1e7;  // samples above land in the last bin
const double kLogRatio = std::log(1.01);
const auto kBins = static_cast<std::size_t>(std::ceil(std::log(kHighest / kLowest) / kLogRatio));

}  // namespace

Quantiles::Quantiles() : bins_(kBins + 1, 0) {}

void Quantiles::add(double value) {
  if (!(value > 0.0)) value = 0.0;  // NaN too
  ++count_;
  sum_ += value;
  last_ = value;
  std::size_t bin = 0;
  if (value >= kLowest) {
    const double steps = std::floor(std::log(value / kLowest) / kLogRatio);
    bin = 1 + std::min(kBins - 1, static_cast<std::size_t>(steps));
  }
  ++bins_[bin];
}

std::optional<double> Quantiles::quantile(double p) const {
  if (count_ == 0) return std::nullopt;
  // Nearest rank: the smallest sample with at least p of all samples at or below it.
  const auto rank = std::max<std::uint64_t>(
      1,
      static_cast<std::uint64_t>(std::ceil(std::clamp(p, 0.0, 1.0) * static_cast<double>(count_))));
  std::uint64_t seen = 0;
  for (std::size_t bin = 0; bin < bins_.size(); ++bin) {
    seen += bins_[bin];
    if (seen < rank) continue;
    if (bin == 0) return 0.0;
    // The bin's geometric centre: kLowest * 1.01^(bin - 1 + 0.5).
    return kLowest * std::exp((static_cast<double>(bin) - 0.5) * kLogRatio);
  }
  return std::nullopt;  // not reached: the last bin holds the rest
}

}  // namespace tessera::core
