#include "tessera/pipeline/stage_timer.h"

#include <algorithm>
#include <numeric>

namespace tessera::pipeline {

double StageTimer::totalMs() const {
  return std::accumulate(samples_ms_.begin(), samples_ms_.end(), 0.0);
}

double StageTimer::meanMs() const {
  return samples_ms_.empty() ? 0.0 : totalMs() / static_cast<double>(samples_ms_.size());
}

double StageTimer::medianMs() const {
  if (samples_ms_.empty()) return 0.0;
  std::vector<double> sorted = samples_ms_;
  const auto middle = sorted.begin() + static_cast<std::ptrdiff_t>(sorted.size() / 2);
  std::nth_element(sorted.begin(), middle, sorted.end());
  return *middle;
}

double StageTimer::aloneFps() const {
  const double total = totalMs();
  return total > 0.0 ? 1000.0 * static_cast<double>(samples_ms_.size()) / total : 0.0;
}

}  // namespace tessera::pipeline
