#include "tessera/core/thinned_series.h"

namespace tessera::core {

void ThinnedSeries::add(double x, double y) {
  if (added_++ % stride_ != 0) return;
  points_.push_back({x, y});
  if (points_.size() <= max_points_) return;
  std::size_t kept = 0;
  for (std::size_t i = 0; i < points_.size(); i += 2) points_[kept++] = points_[i];
  points_.resize(kept);
  stride_ *= 2;
}

std::optional<double> leastSquaresSlope(const std::vector<ThinnedSeries::Point>& points,
                                        double from_x) {
  double sx = 0, sy = 0, sxx = 0, sxy = 0, m = 0;
  for (const ThinnedSeries::Point& p : points) {
    if (p.x < from_x) continue;
    sx += p.x;
    sy += p.y;
    sxx += p.x * p.x;
    sxy += p.x * p.y;
    ++m;
  }
  const double denominator = m * sxx - sx * sx;
  if (m < 2 || denominator <= 0.0) return std::nullopt;
  return (m * sxy - sx * sy) / denominator;
}

}  // namespace tessera::core
