#pragma once
// Colour samples binned into square buckets of the plane, for the neighbours of every texel
// centre of a bitmap: a lookup visits at most 3 x 3 buckets, and building the index is one
// counting sort. It answers as a k-d tree's k-nearest search within a radius would (nearest
// first, ties by index), at a fraction of its cost on samples as dense as a patch's.
#include <cstddef>
#include <cstdint>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "tessera/planes/colour_samples.h"

namespace tessera::texture {

class SampleBuckets {
 public:
  // Samples farther than `radius` (metres) from the rectangle [low, high] of the plane are
  // never a neighbour of a point in it, and are left out.
  SampleBuckets(const std::vector<planes::ColourSample>& samples, double radius,
                const Eigen::Vector2d& low, const Eigen::Vector2d& high);

  // At most max_count samples within the radius of uv (distance <= radius), nearest first:
  // their indices into the samples and their squared distances. Returns how many.
  int nearest(const Eigen::Vector2d& uv, int max_count, std::vector<int>& indices,
              std::vector<double>& distance2);

 private:
  // The kept samples in bucket order (by index within a bucket), so that a lookup reads each
  // row of its buckets as one contiguous run. Positions stay the samples' floats (12 bytes a
  // sample, not 24: a floor tile's index is tens of MB); distances are taken in doubles, from
  // the same values.
  struct Kept {
    float u, v;
    int index;
  };
  std::vector<Kept> kept_;
  double radius_ = 0.0, radius2_ = 0.0;
  double side_ = 1.0;  // the buckets' side, at least the radius
  Eigen::Vector2d origin_ = Eigen::Vector2d::Zero();
  long columns_ = 0, rows_ = 0;
  // Bucket b holds the samples kept_[first_[b]] .. kept_[first_[b + 1] - 1].
  std::vector<std::uint32_t> first_;
  // A lookup's candidates, those within the radius first; kept between lookups.
  std::vector<std::pair<double, int>> found_;
};

}  // namespace tessera::texture
