#pragma once
// FLANN's randomised trees and LSH tables draw from this thread's cv::theRNG(). Seeding it for
// the scope of a build or a match makes the answers reproducible; the caller's generator state
// is restored afterwards.
#include <cstdint>

#include <opencv2/core.hpp>

namespace tessera::match::internal {

class SeededRng {
 public:
  explicit SeededRng(std::uint64_t seed) : saved_(cv::theRNG()) { cv::theRNG() = cv::RNG(seed); }
  ~SeededRng() { cv::theRNG() = saved_; }
  SeededRng(const SeededRng&) = delete;
  SeededRng& operator=(const SeededRng&) = delete;

 private:
  cv::RNG saved_;
};

}  // namespace tessera::match::internal
