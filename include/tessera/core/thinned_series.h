#pragma once
// A series of (x, y) points in bounded memory: every point is kept until `max_points`, then
// every other one, and from then on every second point added, and so on. The kept points stay
// evenly spread over the whole series, enough for a trend (a least-squares slope) over hours.
// Not thread-safe.
#include <cstddef>
#include <optional>
#include <vector>

namespace tessera::core {

class ThinnedSeries {
 public:
  struct Point {
    double x = 0.0, y = 0.0;
  };
  explicit ThinnedSeries(std::size_t max_points = 4096) : max_points_(max_points) {}
  void add(double x, double y);
  const std::vector<Point>& points() const { return points_; }
  std::size_t added() const { return added_; }

 private:
  std::size_t max_points_;
  std::size_t stride_ = 1;  // keep every stride_-th point added
  std::size_t added_ = 0;
  std::vector<Point> points_;
};

// Least-squares slope of y against x over the points with x at or after `from_x`; nothing with
// fewer than two distinct x.
std::optional<double> leastSquaresSlope(const std::vector<ThinnedSeries::Point>& points,
                                        double from_x);

}  // namespace tessera::core
