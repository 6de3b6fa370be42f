#include "tessera/pipeline/stage_timer.h"

namespace tessera::pipeline {

void StageTimer::add(double wall_ms, double cpu_ms) {
  wall_ms_.add(wall_ms);
  cpu_ms_ += cpu_ms;
}

double StageTimer::aloneFps() const {
  const double total = totalMs();
  return total > 0.0 ? 1000.0 * static_cast<double>(count()) / total : 0.0;
}

double StageTimer::cpuMeanMs() const {
  return count() == 0 ? 0.0 : cpu_ms_ / static_cast<double>(count());
}

}  // namespace tessera::pipeline
