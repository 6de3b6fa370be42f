#pragma once
// Wall-time samples of one stage. Each stage owns its timer and is run serially, so no locking.
#include <chrono>
#include <cstddef>
#include <vector>

namespace tessera::pipeline {

class StageTimer {
 public:
  void add(double ms) { samples_ms_.push_back(ms); }
  std::size_t count() const { return samples_ms_.size(); }
  double totalMs() const;
  double meanMs() const;
  double medianMs() const;
  // Frames per second the stage would sustain alone: count / total time.
  double aloneFps() const;
  double lastMs() const { return samples_ms_.empty() ? 0.0 : samples_ms_.back(); }

 private:
  std::vector<double> samples_ms_;
};

// Measures the scope it lives in and adds it to a timer.
class ScopedStageTime {
 public:
  explicit ScopedStageTime(StageTimer& timer)
      : timer_(timer), start_(std::chrono::steady_clock::now()) {}
  ~ScopedStageTime() {
    const auto elapsed = std::chrono::steady_clock::now() - start_;
    timer_.add(std::chrono::duration<double, std::milli>(elapsed).count());
  }
  ScopedStageTime(const ScopedStageTime&) = delete;
  ScopedStageTime& operator=(const ScopedStageTime&) = delete;

 private:
  StageTimer& timer_;
  std::chrono::steady_clock::time_point start_;
};

}  // namespace tessera::pipeline
