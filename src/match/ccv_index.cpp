#include "tessera/match/ccv_index.h"

#include <algorithm>
#include <cmath>

#include <fmt/format.h>
#include <opencv2/core.hpp>
#include <opencv2/flann.hpp>

#include "internal/seeded_rng.h"
#include "tessera/core/error.h"

namespace tessera::match {
namespace {

constexpr std::uint64_t kIndexSeed = 0x7e55e4a;  // any fixed value: reproducible FLANN

// Below this many vectors a linear scan is as fast as the index and exact.
constexpr std::size_t kMinIndexed = 256;
// FLANN leaves visited per query: enough for near-duplicates (a texture seen again) to be found.
constexpr int kIndexChecks = 64;
constexpr int kTrees = 4;

using internal::SeededRng;

}  // namespace

struct CcvIndex::Impl {
  std::vector<float> values;      // every vector, row-major: the indexed ones, then the tail
  std::vector<std::int64_t> ids;  // one per row
  std::vector<bool> removed;      // one per row: skipped by queries
  std::size_t removed_rows = 0;
  std::size_t indexed = 0;  // rows [0, indexed) are in `index`; the rest is the tail
  std::unique_ptr<cv::flann::Index> index;

  // Drops the removed rows; the index is then rebuilt (or dropped when too few rows are left).
  void compact(std::size_t dims) {
    std::size_t kept = 0;
    for (std::size_t row = 0; row < ids.size(); ++row) {
      if (removed[row]) continue;
      std::copy_n(values.begin() + static_cast<std::ptrdiff_t>(row * dims), dims,
                  values.begin() + static_cast<std::ptrdiff_t>(kept * dims));
      ids[kept++] = ids[row];
    }
    values.resize(kept * dims);
    ids.resize(kept);
    removed.assign(kept, false);
    removed_rows = 0;
    index.reset();
    indexed = 0;
    if (kept >= kMinIndexed) rebuild(dims);
  }

  void rebuild(std::size_t dims) {
    const cv::Mat rows(static_cast<int>(ids.size()), static_cast<int>(dims), CV_32F, values.data());
    SeededRng seeded(kIndexSeed);
    // cv::flann::Index keeps its own copy of the rows, so `values` may grow afterwards.
    index = std::make_unique<cv::flann::Index>(rows, cv::flann::KDTreeIndexParams(kTrees),
                                               cvflann::FLANN_DIST_L1);
    indexed = ids.size();
  }
};

CcvIndex::CcvIndex(std::size_t dims) : dims_(dims), impl_(std::make_unique<Impl>()) {
  if (dims == 0) throw core::Error("CcvIndex: vectors must have at least one dimension");
}

CcvIndex::~CcvIndex() = default;
CcvIndex::CcvIndex(CcvIndex&&) noexcept = default;
CcvIndex& CcvIndex::operator=(CcvIndex&&) noexcept = default;

void CcvIndex::add(std::int64_t id, const std::vector<float>& values) {
  if (values.size() != dims_) {
    throw core::Error(fmt::format("CcvIndex::add: vector of length {}, the index holds length {}",
                                  values.size(), dims_));
  }
  impl_->values.insert(impl_->values.end(), values.begin(), values.end());
  impl_->ids.push_back(id);
  impl_->removed.push_back(false);
  const std::size_t tail = impl_->ids.size() - impl_->indexed;
  // Rebuilding once the tail passes an eighth of the index keeps adding amortised O(log n).
  const std::size_t max_tail = std::max(kMinIndexed, impl_->indexed / 8);
  if ((impl_->index == nullptr && impl_->ids.size() >= kMinIndexed) || tail > max_tail) {
    impl_->rebuild(dims_);
  }
}

bool CcvIndex::remove(std::int64_t id) {
  Impl& impl = *impl_;
  bool found = false;
  for (std::size_t row = 0; row < impl.ids.size(); ++row) {
    if (impl.ids[row] != id || impl.removed[row]) continue;
    impl.removed[row] = true;
    ++impl.removed_rows;
    found = true;
  }
  // Compacting once removals pass an eighth keeps each query's wasted visits bounded; below
  // kMinIndexed vectors the exact scan comes back.
  const std::size_t live = impl.ids.size() - impl.removed_rows;
  if (impl.removed_rows > std::max(kMinIndexed, impl.ids.size() / 8) ||
      (impl.index != nullptr && live < kMinIndexed)) {
    impl.compact(dims_);
  }
  return found;
}

std::size_t CcvIndex::size() const { return impl_->ids.size() - impl_->removed_rows; }

std::vector<CcvNeighbour> CcvIndex::query(const std::vector<float>& values, double max_distance,
                                          std::size_t k) const {
  if (values.size() != dims_) {
    throw core::Error(fmt::format("CcvIndex::query: vector of length {}, the index holds length {}",
                                  values.size(), dims_));
  }
  std::vector<CcvNeighbour> found;
  if (k == 0) return found;
  const Impl& impl = *impl_;
  // Distances are recomputed in double from the stored rows, so the index and the tail rank
  // by exactly the same number and ties break by id.
  const auto consider = [&](std::size_t row) {
    if (impl.removed[row]) return;
    const float* v = impl.values.data() + row * dims_;
    double distance = 0.0;
    for (std::size_t i = 0; i < dims_; ++i)
      distance += std::abs(static_cast<double>(v[i]) - values[i]);
    if (distance <= max_distance) found.push_back({impl.ids[row], distance});
  };

  std::size_t first_linear = 0;
  if (impl.index != nullptr) {
    first_linear = impl.indexed;
    // Removed rows may be among the nearest: ask for as many more as there can be.
    const std::size_t wanted = k >= impl.indexed ? k : k + impl.removed_rows;
    const int knn = static_cast<int>(std::min(wanted, impl.indexed));
    const cv::Mat query_row = cv::Mat(values).reshape(1, 1);
    cv::Mat indices, distances;
    impl.index->knnSearch(query_row, indices, distances, knn, cv::flann::SearchParams(kIndexChecks));
    for (int j = 0; j < indices.cols; ++j) {
      const int row = indices.at<int>(0, j);
      if (row >= 0 && static_cast<std::size_t>(row) < impl.indexed) {
        consider(static_cast<std::size_t>(row));
      }
    }
  }
  for (std::size_t row = first_linear; row < impl.ids.size(); ++row) consider(row);

  std::sort(found.begin(), found.end(), [](const CcvNeighbour& a, const CcvNeighbour& b) {
    return a.distance != b.distance ? a.distance < b.distance : a.id < b.id;
  });
  if (found.size() > k) found.resize(k);
  return found;
}

}  // namespace tessera::match
