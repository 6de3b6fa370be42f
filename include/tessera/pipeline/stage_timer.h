#pragma once
// Wall and CPU time of one stage, in bounded memory however long the run (core::Quantiles).
// Each stage owns its timer and is run serially, so no locking.
#include <chrono>
#include <cstddef>

#include "tessera/core/cpu_time.h"
#include "tessera/core/quantiles.h"

namespace tessera::pipeline {

class StageTimer {
 public:
  // `cpu_ms`: CPU time of the thread that ran the call (work it handed to other threads, such
  // as OpenMP or OpenCV workers, is not in it).
  void add(double wall_ms, double cpu_ms = 0.0);
  std::size_t count() const { return wall_ms_.count(); }
  double totalMs() const { return wall_ms_.sum(); }
  double meanMs() const { return wall_ms_.mean(); }
  double medianMs() const { return wall_ms_.quantile(0.5).value_or(0.0); }
  // Frames per second the stage would sustain alone: count / total time.
  double aloneFps() const;
  double lastMs() const { return wall_ms_.last(); }
  double cpuTotalMs() const { return cpu_ms_; }
  double cpuMeanMs() const;

 private:
  core::Quantiles wall_ms_;
  double cpu_ms_ = 0.0;
};

// Measures the scope it lives in (wall time and the thread's CPU time) and adds it to a timer.
class ScopedStageTime {
 public:
  explicit ScopedStageTime(StageTimer& timer)
      : timer_(timer),
        start_(std::chrono::steady_clock::now()),
        cpu_start_s_(core::threadCpuSeconds()) {}
  ~ScopedStageTime() {
    const auto elapsed = std::chrono::steady_clock::now() - start_;
    timer_.add(std::chrono::duration<double, std::milli>(elapsed).count(),
               1e3 * (core::threadCpuSeconds() - cpu_start_s_));
  }
  ScopedStageTime(const ScopedStageTime&) = delete;
  ScopedStageTime& operator=(const ScopedStageTime&) = delete;

 private:
  StageTimer& timer_;
  std::chrono::steady_clock::time_point start_;
  double cpu_start_s_;
};

}  // namespace tessera::pipeline
