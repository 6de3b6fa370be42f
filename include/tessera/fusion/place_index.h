#pragma once
// Place recognition over keyframes: keyframes' ORB descriptors go into FLANN indexes
// (locality-sensitive hashing under the Hamming distance), and a query keyframe's descriptors
// vote for the keyframes whose descriptors lie near them.
//
// FLANN's LSH index cannot grow, so the keyframes are kept in batches of 1, 2, 4, ... units
// of `batch_keyframes`, each with its own index; two batches of the same size are merged into
// one (the logarithmic method). A lookup searches O(log n) indexes and each keyframe is
// re-indexed O(log n) times. The newest keyframes, not yet a unit, are searched linearly; they
// are usually too recent to be revisit candidates and then skipped.
//
// Thread-safety: none; each user owns one (the tracker, to relocalise a lost frame; the loop
// closer's worker, to find revisits).
#include <cstddef>
#include <memory>
#include <vector>

#include <opencv2/core.hpp>

#include "tessera/fusion/feature_pose.h"

namespace cv::flann {
class Index;
}

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

  // Adds keyframe `id`'s descriptors (CV_8U rows of 32 bytes; none is fine).
  void add(int id, const cv::Mat& descriptors);

  // The keyframes that share the most descriptors with `descriptors`, most votes first, each
  // with at least min_votes. A descriptor gives at most one vote to each keyframe.
  std::vector<PlaceCandidate> query(const cv::Mat& descriptors, const PlaceQuery& query) const;

  std::size_t keyframes() const { return keyframe_count_; }
  std::size_t descriptors() const { return owner_.size(); }
  std::size_t indexes() const { return batches_.size(); }

 private:
  struct Batch {
    std::size_t begin = 0, end = 0;  // descriptor rows
    std::size_t units = 1;
    cv::Mat rows;  // the index's own copy of its rows
    std::unique_ptr<cv::flann::Index> index;
  };
  Batch makeBatch(std::size_t begin, std::size_t end, std::size_t units) const;

  std::size_t batch_keyframes_;
  std::size_t keyframe_count_ = 0;
  std::size_t tail_keyframes_ = 0;  // keyframes added since the last batch
  std::vector<int> owner_;          // keyframe id of each descriptor row
  cv::Mat all_;                     // every descriptor, one row each, in owner_ order
  std::vector<Batch> batches_;      // oldest first; rows after the last are the tail
};

}  // namespace tessera::fusion
