#include "internal/sample_buckets.h"

#include <algorithm>
#include <cmath>

namespace tessera::texture {

namespace {

// At most this many buckets per sample kept: a few samples spread far apart get wider buckets
// rather than a huge empty index.
constexpr double kBucketsPerSample = 4.0;

}  // namespace

SampleBuckets::SampleBuckets(const std::vector<planes::ColourSample>& samples, double radius,
                             const Eigen::Vector2d& low, const Eigen::Vector2d& high)
    : radius_(radius), radius2_(radius * radius) {
  std::vector<int> kept;
  kept.reserve(samples.size());
  for (std::size_t i = 0; i < samples.size(); ++i) {
    const Eigen::Vector2d p(samples[i].u, samples[i].v);
    if ((p.array() >= low.array() - radius).all() && (p.array() <= high.array() + radius).all()) {
      kept.push_back(static_cast<int>(i));
    }
  }
  origin_ = low.array() - radius;
  const Eigen::Vector2d extent = (high - low).array() + 2.0 * radius;
  side_ = std::max(radius, 1e-9);
  const double most = std::max(1.0, kBucketsPerSample * static_cast<double>(kept.size()));
  if (extent.x() * extent.y() / (side_ * side_) > most) {
    side_ = std::sqrt(extent.x() * extent.y() / most);
  }
  columns_ = static_cast<long>(std::floor(extent.x() / side_)) + 1;
  rows_ = static_cast<long>(std::floor(extent.y() / side_)) + 1;

  // Counting sort of the kept samples by bucket, in index order within a bucket.
  auto bucketOf = [&](int i) {
    const planes::ColourSample& s = samples[static_cast<std::size_t>(i)];
    const long x = std::clamp(static_cast<long>((s.u - origin_.x()) / side_), 0L, columns_ - 1);
    const long y = std::clamp(static_cast<long>((s.v - origin_.y()) / side_), 0L, rows_ - 1);
    return static_cast<std::size_t>(y * columns_ + x);
  };
  first_.assign(static_cast<std::size_t>(columns_ * rows_) + 1, 0);
  for (int i : kept) ++first_[bucketOf(i) + 1];
  for (std::size_t b = 1; b < first_.size(); ++b) first_[b] += first_[b - 1];
  kept_.resize(kept.size());
  std::vector<std::uint32_t> next(first_.begin(), first_.end() - 1);
  for (int i : kept) {
    const planes::ColourSample& s = samples[static_cast<std::size_t>(i)];
    kept_[next[bucketOf(i)]++] = {s.u, s.v, i};
  }
}

int SampleBuckets::nearest(const Eigen::Vector2d& uv, int max_count, std::vector<int>& indices,
                           std::vector<double>& distance2) {
  indices.clear();
  distance2.clear();
  const double radius = radius_;
  const long x0 =
      std::max(0L, static_cast<long>(std::floor((uv.x() - radius - origin_.x()) / side_)));
  const long y0 =
      std::max(0L, static_cast<long>(std::floor((uv.y() - radius - origin_.y()) / side_)));
  const long x1 = std::min(columns_ - 1,
                           static_cast<long>(std::floor((uv.x() + radius - origin_.x()) / side_)));
  const long y1 =
      std::min(rows_ - 1, static_cast<long>(std::floor((uv.y() + radius - origin_.y()) / side_)));
  if (x0 > x1 || y0 > y1) return 0;  // uv lies farther than the radius from every bucket
  // Buckets x0..x1 of a row are one run of kept_. Every candidate is written and only those
  // within the radius advance the count: no branch to mispredict on half of them.
  std::size_t candidates = 0;
  for (long y = y0; y <= y1; ++y) {
    candidates += first_[static_cast<std::size_t>(y * columns_ + x1 + 1)] -
                  first_[static_cast<std::size_t>(y * columns_ + x0)];
  }
  if (found_.size() < candidates) found_.resize(candidates);
  std::size_t within = 0;
  for (long y = y0; y <= y1; ++y) {
    const Kept* k = kept_.data() + first_[static_cast<std::size_t>(y * columns_ + x0)];
    const Kept* end = kept_.data() + first_[static_cast<std::size_t>(y * columns_ + x1 + 1)];
    for (; k < end; ++k) {
      const double du = static_cast<double>(k->u) - uv.x();
      const double dv = static_cast<double>(k->v) - uv.y();
      const double d2 = du * du + dv * dv;
      found_[within] = {d2, k->index};
      within += d2 <= radius2_ ? 1 : 0;
    }
  }
  // Nearest first, ties by index. A full sort when all are taken (the usual case): the same
  // order, and cheaper on a handful than a partial sort's heap.
  const auto first = found_.begin();
  const auto count = std::min(within, static_cast<std::size_t>(std::max(max_count, 0)));
  if (count == within) {
    std::sort(first, first + static_cast<long>(within));
  } else {
    std::partial_sort(first, first + static_cast<long>(count), first + static_cast<long>(within));
  }
  for (std::size_t j = 0; j < count; ++j) {
    distance2.push_back(found_[j].first);
    indices.push_back(found_[j].second);
  }
  return static_cast<int>(count);
}

}  // namespace tessera::texture
