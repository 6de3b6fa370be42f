// The CCV index against a plain linear scan: exact below the index threshold, nearly always
// the same nearest neighbour above it, and vectors added after a build are still found.
#include "tessera/match/ccv_index.h"

#include <algorithm>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "tessera/core/error.h"
#include "tessera/match/ccv.h"

namespace tessera::match {
namespace {

constexpr std::size_t kDims = 128;  // the default CcvConfig: 2 x 4^3

// CCV-like: a few bins of weight summing to 1, the rest 0.
std::vector<float> randomCcv(std::mt19937& random) {
  std::uniform_int_distribution<std::size_t> bin(0, kDims - 1);
  std::uniform_real_distribution<float> weight(0.0F, 1.0F);
  std::vector<float> v(kDims, 0.0F);
  float sum = 0.0F;
  for (int i = 0; i < 8; ++i) {
    const float w = weight(random);
    v[bin(random)] += w;
    sum += w;
  }
  for (float& x : v) x /= sum;
  return v;
}

// The same texture seen again: every bin moved a little, mass shifted between a few bins.
std::vector<float> perturbed(std::vector<float> v, std::mt19937& random) {
  std::uniform_int_distribution<std::size_t> bin(0, kDims - 1);
  std::uniform_real_distribution<float> shift(0.0F, 0.02F);
  for (int i = 0; i < 4; ++i) {
    const std::size_t from = bin(random), to = bin(random);
    const float moved = std::min(v[from], shift(random));
    v[from] -= moved;
    v[to] += moved;
  }
  return v;
}

// The slow reference: every vector, sorted by distance then id.
std::vector<CcvNeighbour> linearScan(const std::vector<std::vector<float>>& all,
                                     const std::vector<float>& query, double max_distance,
                                     std::size_t k) {
  std::vector<CcvNeighbour> found;
  for (std::size_t i = 0; i < all.size(); ++i) {
    const double d = ccvDistance(all[i], query);
    if (d <= max_distance) found.push_back({static_cast<std::int64_t>(i), d});
  }
  std::sort(found.begin(), found.end(), [](const CcvNeighbour& a, const CcvNeighbour& b) {
    return a.distance != b.distance ? a.distance < b.distance : a.id < b.id;
  });
  if (found.size() > k) found.resize(k);
  return found;
}

void expectSame(const std::vector<CcvNeighbour>& got, const std::vector<CcvNeighbour>& want) {
  ASSERT_EQ(got.size(), want.size());
  for (std::size_t i = 0; i < got.size(); ++i) {
    EXPECT_EQ(got[i].id, want[i].id) << "rank " << i;
    EXPECT_NEAR(got[i].distance, want[i].distance, 1e-9) << "rank " << i;
  }
}

TEST(CcvIndex, BelowTheIndexThresholdAnswersEqualALinearScan) {
  std::mt19937 random(11);
  CcvIndex index(kDims);
  std::vector<std::vector<float>> all;
  for (int i = 0; i < 200; ++i) {
    all.push_back(randomCcv(random));
    index.add(i, all.back());
  }
  all.push_back(all[17]);  // a duplicate: ties go to the lower id
  index.add(200, all.back());
  EXPECT_EQ(index.size(), 201u);
  for (int q = 0; q < 50; ++q) {
    const std::vector<float> query =
        q % 2 == 0 ? perturbed(all[static_cast<std::size_t>(q)], random) : randomCcv(random);
    expectSame(index.query(query, 2.0, 10), linearScan(all, query, 2.0, 10));
    expectSame(index.query(query, 1.2, 500), linearScan(all, query, 1.2, 500));
  }
  const auto tied = index.query(all[17], 0.0, 5);
  ASSERT_EQ(tied.size(), 2u);
  EXPECT_EQ(tied[0].id, 17);
  EXPECT_EQ(tied[1].id, 200);
  EXPECT_TRUE(index.query(all[3], 1.0, 0).empty());
}

TEST(CcvIndex, WithManyVectorsTheNearestIsNearlyAlwaysTheLinearScansNearest) {
  std::mt19937 random(12);
  CcvIndex index(kDims);
  std::vector<std::vector<float>> all;
  for (int i = 0; i < 5000; ++i) {
    all.push_back(randomCcv(random));
    index.add(i, all.back());
  }
  std::uniform_int_distribution<std::size_t> pick(0, all.size() - 1);
  int same = 0;
  for (int q = 0; q < 100; ++q) {
    const std::vector<float> query = perturbed(all[pick(random)], random);
    const auto want = linearScan(all, query, 2.0, 1);
    const auto got = index.query(query, 2.0, 5);
    ASSERT_FALSE(got.empty());
    ASSERT_LE(got.size(), 5u);
    EXPECT_TRUE(std::is_sorted(
        got.begin(), got.end(),
        [](const CcvNeighbour& a, const CcvNeighbour& b) { return a.distance < b.distance; }));
    // Whatever the index returns carries its true distance.
    for (const auto& n : got) {
      EXPECT_NEAR(n.distance, ccvDistance(all[static_cast<std::size_t>(n.id)], query), 1e-9);
    }
    if (got[0].id == want[0].id) ++same;
  }
  EXPECT_GE(same, 95);
  // max_distance filters: nothing lies within 0 of a vector no one added.
  EXPECT_TRUE(index.query(randomCcv(random), 0.0, 5).empty());
}

TEST(CcvIndex, VectorsAddedAfterTheBuildAreFoundBeforeAndAfterTheRebuild) {
  std::mt19937 random(13);
  CcvIndex index(kDims);
  for (int i = 0; i < 2000; ++i) index.add(i, randomCcv(random));
  // 2000 indexed: the tail may grow to 256 before a rebuild, so these sit in the tail...
  std::vector<std::vector<float>> late;
  for (int i = 0; i < 100; ++i) {
    late.push_back(randomCcv(random));
    index.add(10000 + i, late.back());
  }
  for (int i = 0; i < 100; ++i) {
    const auto got = index.query(late[static_cast<std::size_t>(i)], 0.5, 1);
    ASSERT_EQ(got.size(), 1u);
    EXPECT_EQ(got[0].id, 10000 + i);
    EXPECT_DOUBLE_EQ(got[0].distance, 0.0);
  }
  // ...and these push it past the threshold, into a rebuilt index.
  for (int i = 0; i < 300; ++i) index.add(20000 + i, randomCcv(random));
  EXPECT_EQ(index.size(), 2400u);
  int found = 0;
  for (int i = 0; i < 100; ++i) {
    const auto got = index.query(late[static_cast<std::size_t>(i)], 0.5, 1);
    if (!got.empty() && got[0].id == 10000 + i) ++found;
  }
  EXPECT_GE(found, 98);  // exact copies: the leaf holding the vector itself is searched first
}

// Removed vectors are never answered, in the tail, in the index and after the compaction that
// enough removals bring; what is left answers as a linear scan over it.
TEST(CcvIndex, RemovedVectorsAreNeverFound) {
  std::mt19937 random(14);
  CcvIndex index(kDims);
  std::vector<std::vector<float>> all;
  for (int i = 0; i < 1200; ++i) {
    all.push_back(randomCcv(random));
    index.add(i, all.back());
  }
  // Ids stay positions in `all`; a removed one's row there moves far from every query.
  const std::vector<float> far(kDims, 1e3F);
  const auto removeEvery = [&](int step, int offset) {
    for (int i = offset; i < 1200; i += step) {
      if (all[static_cast<std::size_t>(i)] == far) continue;
      EXPECT_TRUE(index.remove(i));
      all[static_cast<std::size_t>(i)] = far;
    }
  };
  removeEvery(10, 3);  // 120 removed: below the compaction threshold (256)
  EXPECT_EQ(index.size(), 1080u);
  EXPECT_FALSE(index.remove(3));  // already gone
  EXPECT_FALSE(index.remove(5000));
  for (int i = 3; i < 1200; i += 50) {
    // Its own vector asked for: anything but itself.
    for (const CcvNeighbour& n : index.query(all[static_cast<std::size_t>(i + 1)], 2.0, 20)) {
      EXPECT_NE(n.id % 10, 3) << n.id;
    }
  }
  removeEvery(3, 0);  // past the threshold: compacted and rebuilt
  const std::size_t kept = static_cast<std::size_t>(
      std::count_if(all.begin(), all.end(), [&](const auto& v) { return v != far; }));
  EXPECT_EQ(index.size(), kept);
  int asked = 0, same = 0;
  for (std::size_t id = 1; id < all.size(); id += 7) {
    const bool gone = all[id] == far;
    const std::vector<float> query = gone ? randomCcv(random) : perturbed(all[id], random);
    const auto got = index.query(query, 2.0, 5);
    for (const CcvNeighbour& n : got) EXPECT_NE(all[static_cast<std::size_t>(n.id)], far) << n.id;
    if (gone) continue;  // a random query: only that nothing removed comes back
    const auto want = linearScan(all, query, 2.0, 1);
    ++asked;
    if (!got.empty() && got[0].id == want.at(0).id) ++same;
  }
  EXPECT_GE(same, asked * 95 / 100) << asked;  // as an index that never removed anything
  // Below the index threshold again: exact.
  for (int i = 0; i < 1200; ++i) {
    if (all[static_cast<std::size_t>(i)] != far && i % 4 != 0) {
      index.remove(i);
      all[static_cast<std::size_t>(i)] = far;
    }
  }
  ASSERT_LT(index.size(), 256u);
  for (int q = 0; q < 20; ++q) {
    const std::vector<float> query = randomCcv(random);
    expectSame(index.query(query, 2.0, 10), linearScan(all, query, 2.0, 10));
  }
}

TEST(CcvIndex, WrongLengthsThrowAndMovingKeepsTheContents) {
  EXPECT_THROW(CcvIndex(0), core::Error);
  CcvIndex index(4);
  EXPECT_THROW(index.add(1, {1.0F, 2.0F}), core::Error);
  index.add(1, {0.5F, 0.5F, 0.0F, 0.0F});
  EXPECT_THROW(index.query({1.0F}, 1.0, 1), core::Error);
  CcvIndex moved = std::move(index);
  EXPECT_EQ(moved.size(), 1u);
  EXPECT_EQ(moved.query({0.5F, 0.5F, 0.0F, 0.0F}, 0.0, 1).at(0).id, 1);
}

}  // namespace
}  // namespace tessera::match
