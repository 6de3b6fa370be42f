#pragma once
// Nearest CCVs among many, without a linear scan: a FLANN index (OpenCV's, randomised k-d
// trees under the L1 distance) over the vectors, plus a short list of the vectors added since
// it was built, scanned linearly; the index is rebuilt once that list grows past an eighth of
// it (at least 256), so adding costs amortised O(log n) and a query O(checks + tail). A removed
// vector is skipped until removals pass an eighth of the rows (at least 256), or fewer than 256
// are left; the rows are then compacted and the index rebuilt (or dropped).
// Not thread-safe by itself: the caller guards add() against concurrent queries.
#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

namespace tessera::match {

struct CcvNeighbour {
  std::int64_t id = 0;
  double distance = 0.0;  // ccvDistance
};

class CcvIndex {
 public:
  explicit CcvIndex(std::size_t dims);
  ~CcvIndex();
  CcvIndex(CcvIndex&&) noexcept;
  CcvIndex& operator=(CcvIndex&&) noexcept;

  void add(std::int64_t id, const std::vector<float>& values);
  // Removes every vector added under `id`; returns whether there was one.
  bool remove(std::int64_t id);
  std::size_t size() const;  // vectors not removed
  std::size_t dims() const { return dims_; }

  // At most k vectors within max_distance of `values`, nearest first (ties: lower id first).
  // Approximate once the index is built: FLANN visits `checks` leaves.
  std::vector<CcvNeighbour> query(const std::vector<float>& values, double max_distance,
                                  std::size_t k) const;

 private:
  struct Impl;
  std::size_t dims_;
  std::unique_ptr<Impl> impl_;
};

}  // namespace tessera::match
