#pragma once
// Quantiles of a stream of non-negative samples (times in ms, latencies) in bounded memory: a
// histogram over logarithmic bins, each 1 % wider than the one before, from 1e-3 to 1e7. A
// quantile is the geometric centre of the bin it falls in, so within 0.5 % of the exact
// nearest-rank value; count, sum and mean are exact. Hours of samples fit in the same 18 KB.
// Not thread-safe: one writer, or a lock around it.
#include <cstddef>
#include <cstdint>
#include <optional>
#include <vector>

namespace tessera::core {

class Quantiles {
 public:
  Quantiles();
  // Negative and NaN samples count as 0.
  void add(double value);
  std::size_t count() const { return count_; }
  double sum() const { return sum_; }
  double mean() const { return count_ == 0 ? 0.0 : sum_ / static_cast<double>(count_); }
  double last() const { return last_; }
  // The p-quantile (nearest rank, p in [0, 1]); nothing before the first sample.
  std::optional<double> quantile(double p) const;

 private:
  std::vector<std::uint64_t> bins_;  // [0]: samples below the first bin's edge (0 included)
  std::size_t count_ = 0;
  double sum_ = 0.0;
  double last_ = 0.0;
};

}  // namespace tessera::core
