#include "tessera/fusion/place_index.h"

#include <bitset>
#include <random>

#include <gtest/gtest.h>

namespace tessera::fusion {
namespace {

constexpr int kPerKeyframe = 1000;

cv::Mat randomDescriptors(int rows, std::mt19937& random) {
  cv::Mat out(rows, 32, CV_8U);
  std::uniform_int_distribution<int> byte(0, 255);
  for (int r = 0; r < rows; ++r) {
    for (int c = 0; c < 32; ++c) out.at<uchar>(r, c) = static_cast<uchar>(byte(random));
  }
  return out;
}

// `descriptors` with `flips` distinct random bits of each row flipped.
cv::Mat flipped(const cv::Mat& descriptors, int flips, std::mt19937& random) {
  cv::Mat out = descriptors.clone();
  std::uniform_int_distribution<int> bit(0, 255);
  for (int r = 0; r < out.rows; ++r) {
    std::bitset<256> done;
    while (static_cast<int>(done.count()) < flips) {
      const int b = bit(random);
      if (done[static_cast<std::size_t>(b)]) continue;
      done.set(static_cast<std::size_t>(b));
      out.at<uchar>(r, b / 8) ^= static_cast<uchar>(1u << (b % 8));
    }
  }
  return out;
}

TEST(PlaceIndex, FindsTheKeyframeWhoseDescriptorsAQueryRepeatsWithAFewBitsChanged) {
  std::mt19937 random(7);
  PlaceIndex index(4);
  std::vector<cv::Mat> keyframes;
  for (int id = 0; id < 37; ++id) {
    keyframes.push_back(randomDescriptors(kPerKeyframe, random));
    index.add(id, keyframes.back());
  }
  // 37 keyframes in units of 4: nine units, merged into batches of 32 and 4 keyframes, then a
  // tail of 1.
  EXPECT_EQ(index.indexes(), 2u);
  EXPECT_EQ(index.descriptors(), 37u * kPerKeyframe);

  PlaceQuery query;
  query.max_distance = 40;
  query.min_votes = 20;
  for (const int id : {0, 20, 31, 33, 36}) {  // in each batch, and in the tail
    // 300 of the keyframe's descriptors, 3 bits of each changed (image noise).
    const cv::Mat probe = flipped(keyframes[static_cast<std::size_t>(id)].rowRange(0, 300), 3, random);
    const std::vector<PlaceCandidate> found = index.query(probe, query);
    ASSERT_FALSE(found.empty()) << "keyframe " << id;
    EXPECT_EQ(found.front().keyframe, id);
    // A descriptor is missed only when each table's 20 key bits hold a changed one:
    // (1 - (253/256)^20)^4, about 0.2 %.
    EXPECT_GE(found.front().votes, 290) << "keyframe " << id;
    // Random descriptors lie about 128 bits apart: no other keyframe gets votes.
    EXPECT_EQ(found.size(), 1u) << "keyframe " << id;
  }
  // A place never seen finds nothing.
  EXPECT_TRUE(index.query(randomDescriptors(300, random), query).empty());
  // Keyframes newer than newest_allowed are no candidates.
  query.newest_allowed = 30;
  EXPECT_TRUE(index.query(flipped(keyframes[35].rowRange(0, 300), 3, random), query).empty());
}

TEST(PlaceIndex, HoldsAFewTensOfBytesPerDescriptor) {
  std::mt19937 random(11);
  PlaceIndex index(8);
  for (int id = 0; id < 64; ++id) index.add(id, randomDescriptors(kPerKeyframe, random));
  // The descriptor (32 bytes, shared with the caller), its owner (4), where its row lies (8)
  // and a (key, row) pair per table (8 each): 76 bytes, and some slack in the arrays.
  const double per_descriptor =
      static_cast<double>(index.bytes()) / static_cast<double>(index.descriptors());
  EXPECT_GE(per_descriptor, 76.0);
  EXPECT_LE(per_descriptor, 100.0);
}

// The index shares a keyframe's descriptors instead of copying them, and stays right when the
// caller lets its matrix go; a matrix over the caller's own buffer is copied, since the
// caller may write the buffer again.
TEST(PlaceIndex, SharesOwnedDescriptorsAndCopiesBorrowedOnes) {
  std::mt19937 random(13);
  PlaceIndex index(2);
  cv::Mat owned = randomDescriptors(kPerKeyframe, random);
  const cv::Mat owned_probe = flipped(owned.rowRange(0, 300), 3, random);
  index.add(0, owned);
  owned.release();  // the index's reference keeps the data
  std::vector<uchar> buffer(static_cast<std::size_t>(kPerKeyframe) * 32);
  const cv::Mat source = randomDescriptors(kPerKeyframe, random);
  std::copy(source.datastart, source.dataend, buffer.begin());
  index.add(1, cv::Mat(kPerKeyframe, 32, CV_8U, buffer.data()));
  std::fill(buffer.begin(), buffer.end(), uchar{0});  // the caller reuses its buffer
  for (int id = 2; id < 8; ++id) index.add(id, randomDescriptors(kPerKeyframe, random));

  const PlaceQuery query;
  for (const auto& [id, probe] :
       {std::pair{0, owned_probe}, std::pair{1, flipped(source.rowRange(0, 300), 3, random)}}) {
    const std::vector<PlaceCandidate> found = index.query(probe, query);
    ASSERT_FALSE(found.empty()) << "keyframe " << id;
    EXPECT_EQ(found.front().keyframe, id);
    EXPECT_GE(found.front().votes, 290) << "keyframe " << id;
  }
}

// A removed keyframe is never a candidate again, lets its descriptors go and loses its table
// entries when its batch is merged; the others are found as before.
TEST(PlaceIndex, RemovedKeyframesAreNoCandidatesAndLetTheirDescriptorsGo) {
  std::mt19937 random(17);
  PlaceIndex index(4), all(4);
  std::vector<cv::Mat> keyframes;
  const auto add = [&](int id) {
    keyframes.push_back(randomDescriptors(kPerKeyframe, random));
    index.add(id, keyframes.back());
    all.add(id, keyframes.back());
  };
  for (int id = 0; id < 8; ++id) add(id);
  index.remove(2);   // in a batch
  index.remove(2);   // again: nothing more
  index.remove(20);  // not added: ignored
  EXPECT_EQ(index.keyframes(), 7u);
  EXPECT_EQ(keyframes[2].u->refcount, 2);  // the caller's and the other index's
  EXPECT_EQ(index.bytes(), all.bytes() - 32u * kPerKeyframe);
  for (int id = 8; id < 12; ++id) add(id);
  index.remove(9);  // in the tail
  for (int id = 12; id < 16; ++id) add(id);
  // Units of 4 merged into one batch of 16 keyframes: the removed ones' entries (8 bytes in
  // each table) are gone too.
  EXPECT_EQ(index.indexes(), 1u);
  EXPECT_EQ(index.bytes(), all.bytes() - 2u * (32u + 8u * PlaceIndex::kTables) * kPerKeyframe);

  const PlaceQuery query;
  for (int id = 0; id < 16; ++id) {
    const cv::Mat probe =
        flipped(keyframes[static_cast<std::size_t>(id)].rowRange(0, 300), 3, random);
    const std::vector<PlaceCandidate> found = index.query(probe, query);
    if (id == 2 || id == 9) {
      EXPECT_TRUE(found.empty()) << "keyframe " << id;
      continue;
    }
    ASSERT_FALSE(found.empty()) << "keyframe " << id;
    EXPECT_EQ(found.front().keyframe, id);
    EXPECT_GE(found.front().votes, 290) << "keyframe " << id;
  }
}

}  // namespace
}  // namespace tessera::fusion
