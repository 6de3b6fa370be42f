#pragma once
// Place recognition over keyframes: keyframes' ORB descriptors are hashed into a few tables
// (locality-sensitive hashing under the Hamming distance: each table's key is a fixed random
// choice of the descriptor's bits), and a query keyframe's descriptors vote for the keyframes
// whose descriptors share a key with them and lie near.
//
// Each table is a sorted array of (key, row) pairs, 8 bytes per descriptor. FLANN's LSH index,
// used before, kept a hash map node and a vector per key: about 300 bytes per descriptor, 240
// MB for the loop lap's 700,000 descriptors. A sorted array cannot grow in place either, so the
// keyframes are kept in batches of 1, 2, 4, ... units of `batch_keyframes`; two batches of the
// same size are merged into one (the logarithmic method). A lookup searches O(log n) batches
// and each descriptor is merged O(log n) times. The newest keyframes, not yet a unit, are
// searched linearly; they are usually too recent to be revisit candidates and then skipped.
//
// Thread-safety: none; each user owns one (the tracker, to relocalise a lost frame; the loop
// closer's worker, to find revisits).
#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include <opencv2/core.hpp>

#include "tessera/fusion/feature_pose.h"

namespace tessera::fusion {

struct PlaceCandidate {
  int keyframe = -1;  // id given to add()
  int votes = 0;
};

struct PlaceQuery {
  int max_distance = 40;   // Hamming distance below which a neighbour votes
  int neighbours = 4;      // nearest neighbours looked at per descriptor
  int min_votes = 20;
  int max_candidates = 3;
  int newest_allowed = -1;  // keyframes with a larger id are not candidates (-1: all)
};

// The descriptors of the `count` keypoints of `features` with the strongest response (ORB's
// corner score): a query's votes come from them.
cv::Mat strongestDescriptors(const FeatureFrame& features, int count);

class PlaceIndex {
 public:
  explicit PlaceIndex(std::size_t batch_keyframes = 8);
  ~PlaceIndex();
  PlaceIndex(const PlaceIndex&) = delete;
  PlaceIndex& operator=(const PlaceIndex&) = delete;

  // Adds keyframe `id`'s descriptors (CV_8U rows of 32 bytes; none is fine). The index shares
  // the matrix's data with the caller (the keyframe keeps the same descriptors), so it must
  // not be written afterwards; a matrix that does not own its data, or is not continuous, is
  // copied.
  void add(int id, const cv::Mat& descriptors);

  // Keyframe `id` is no longer a candidate: its descriptors are let go (the index no longer
  // shares them), its rows skipped, and their entries dropped when their batch is next merged.
  // Ids must have been added in ascending order; an id not in the index is ignored.
  void remove(int id);

  // The keyframes that share the most descriptors with `descriptors`, most votes first, each
  // with at least min_votes. A descriptor gives at most one vote to each keyframe.
  std::vector<PlaceCandidate> query(const cv::Mat& descriptors, const PlaceQuery& query) const;

  std::size_t keyframes() const { return keyframe_count_ - removed_keyframes_; }
  std::size_t descriptors() const { return owner_.size(); }
  std::size_t indexes() const { return batches_.size(); }
  // Heap bytes held: the descriptors (shared with the keyframes), their owners and rows, and
  // the hash tables.
  std::size_t bytes() const;

  static constexpr int kTables = 4;    // hash tables
  static constexpr int kKeyBits = 20;  // bits of a descriptor in a table's key

 private:
  struct Entry {
    std::uint32_t key = 0;
    std::uint32_t row = 0;  // descriptor row (rows_)
    friend bool operator<(const Entry& a, const Entry& b) {
      return a.key != b.key ? a.key < b.key : a.row < b.row;
    }
  };
  // A table's entries sorted by key, then row, with where each value of the key's top
  // kDirectoryBits begins: a lookup searches a few dozen entries, not the whole array.
  struct Table {
    std::vector<Entry> entries;
    std::vector<std::uint32_t> starts;  // 2^kDirectoryBits + 1 offsets into entries
  };
  struct Batch {
    std::size_t begin = 0, end = 0;  // descriptor rows
    std::size_t units = 1;
    std::array<Table, kTables> tables;
  };
  static constexpr int kDirectoryBits = 12;
  static void index(Table& table);
  std::uint32_t keyOf(int table, const unsigned char* descriptor) const;
  Batch makeBatch(std::size_t begin, std::size_t end) const;
  Batch merge(const Batch& older, const Batch& newer) const;
  // The `k` rows of `batch` nearest to `descriptor` among those sharing a key with it, nearest
  // first (ties by row), with their distances.
  void nearestInBatch(const Batch& batch, const unsigned char* descriptor, int k,
                      std::vector<std::pair<int, std::uint32_t>>& found) const;

  std::array<std::array<std::uint8_t, kKeyBits>, kTables> key_bits_{};  // bit of each key bit
  std::size_t batch_keyframes_;
  std::size_t keyframe_count_ = 0;
  std::size_t tail_keyframes_ = 0;  // keyframes added since the last batch
  std::vector<int> owner_;          // keyframe id of each descriptor row
  // Every descriptor row, in owner_ order, where it lies in the matrices added (held_, one per
  // keyframe with descriptors, whose ids are held_ids_). Shared rather than copied into one
  // matrix: the copy doubled the descriptors' memory, and a growing matrix keeps up to half of
  // its capacity unused. A removed keyframe's rows are null.
  std::vector<const uchar*> rows_;
  std::vector<cv::Mat> held_;
  std::vector<int> held_ids_;
  std::size_t removed_keyframes_ = 0;
  std::vector<Batch> batches_;      // oldest first; rows after the last are the tail
};

}  // namespace tessera::fusion
