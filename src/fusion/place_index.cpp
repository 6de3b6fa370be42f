#include "tessera/fusion/place_index.h"

#include <algorithm>
#include <map>
#include <numeric>
#include <random>
#include <set>

#include <opencv2/core/hal/hal.hpp>

namespace tessera::fusion {

namespace {
// LSH parameters: 4 tables of 20-bit keys, no multi-probe. Measured on the loop scene: 12
// tables of 20 bits with multi-probe 2 took 402 ms a lookup, 6 tables of 14 bits 31.6 ms a
// keyframe, these 13.5 ms, for about as many candidates and verified revisits.
constexpr int kOrbDescriptorBytes = 32;
constexpr std::uint32_t kBitChoiceSeed = 20141;
}  // namespace

PlaceIndex::PlaceIndex(std::size_t batch_keyframes)
    : batch_keyframes_(std::max<std::size_t>(1, batch_keyframes)) {
  // Each table keys on its own bits, drawn without repeats from the descriptor's 256.
  std::mt19937 random(kBitChoiceSeed);
  std::array<std::uint8_t, kOrbDescriptorBytes * 8> bits{};
  std::iota(bits.begin(), bits.end(), std::uint8_t{0});
  for (auto& table : key_bits_) {
    std::shuffle(bits.begin(), bits.end(), random);
    std::copy_n(bits.begin(), kKeyBits, table.begin());
  }
}

PlaceIndex::~PlaceIndex() = default;

std::uint32_t PlaceIndex::keyOf(int table, const unsigned char* descriptor) const {
  std::uint32_t key = 0;
  for (const std::uint8_t bit : key_bits_[static_cast<std::size_t>(table)]) {
    key = (key << 1) | ((descriptor[bit >> 3] >> (bit & 7)) & 1u);
  }
  return key;
}

void PlaceIndex::index(Table& table) {
  table.starts.assign((std::size_t{1} << kDirectoryBits) + 1, 0);
  for (const Entry& entry : table.entries)
    ++table.starts[(entry.key >> (kKeyBits - kDirectoryBits)) + 1];
  std::partial_sum(table.starts.begin(), table.starts.end(), table.starts.begin());
}

PlaceIndex::Batch PlaceIndex::makeBatch(std::size_t begin, std::size_t end) const {
  Batch batch;
  batch.begin = begin;
  batch.end = end;
  for (int t = 0; t < kTables; ++t) {
    Table& table = batch.tables[static_cast<std::size_t>(t)];
    std::vector<Entry>& entries = table.entries;
    entries.reserve(end - begin);
    for (std::size_t row = begin; row < end; ++row) {
      if (rows_[row] != nullptr) {
        entries.push_back({keyOf(t, rows_[row]), static_cast<std::uint32_t>(row)});
      }
    }
    std::sort(entries.begin(), entries.end());
    index(table);
  }
  return batch;
}

PlaceIndex::Batch PlaceIndex::merge(const Batch& older, const Batch& newer) const {
  Batch merged;
  merged.begin = older.begin;
  merged.end = newer.end;
  merged.units = older.units + newer.units;
  for (std::size_t t = 0; t < older.tables.size(); ++t) {
    const std::vector<Entry>& a = older.tables[t].entries;
    const std::vector<Entry>& b = newer.tables[t].entries;
    std::vector<Entry>& entries = merged.tables[t].entries;
    entries.reserve(a.size() + b.size());
    std::merge(a.begin(), a.end(), b.begin(), b.end(), std::back_inserter(entries));
    // A removed keyframe's entries go here.
    entries.erase(std::remove_if(entries.begin(), entries.end(),
                                 [this](const Entry& e) { return rows_[e.row] == nullptr; }),
                  entries.end());
    entries.shrink_to_fit();
    index(merged.tables[t]);
  }
  return merged;
}

void PlaceIndex::add(int id, const cv::Mat& descriptors) {
  ++keyframe_count_;
  if (!descriptors.empty()) {
    CV_Assert(descriptors.type() == CV_8U && descriptors.cols == kOrbDescriptorBytes);
    const bool shareable = descriptors.isContinuous() && descriptors.u != nullptr;
    const cv::Mat& held = held_.emplace_back(shareable ? descriptors : descriptors.clone());
    held_ids_.push_back(id);
    for (int r = 0; r < held.rows; ++r) rows_.push_back(held.ptr<uchar>(r));
    owner_.insert(owner_.end(), static_cast<std::size_t>(descriptors.rows), id);
  }
  if (++tail_keyframes_ < batch_keyframes_) return;
  tail_keyframes_ = 0;
  const std::size_t begin = batches_.empty() ? 0 : batches_.back().end;
  if (begin == owner_.size()) return;  // keyframes without descriptors
  batches_.push_back(makeBatch(begin, owner_.size()));
  while (batches_.size() >= 2 && batches_[batches_.size() - 2].units == batches_.back().units) {
    Batch merged = merge(batches_[batches_.size() - 2], batches_.back());
    batches_.pop_back();
    batches_.back() = std::move(merged);
  }
}

void PlaceIndex::remove(int id) {
  const auto held = std::lower_bound(held_ids_.begin(), held_ids_.end(), id);
  const auto first = std::lower_bound(owner_.begin(), owner_.end(), id);
  if (first == owner_.end() || *first != id || held == held_ids_.end() || *held != id) return;
  if (rows_[static_cast<std::size_t>(first - owner_.begin())] == nullptr) return;  // removed
  const auto last = std::upper_bound(first, owner_.end(), id);
  std::fill(rows_.begin() + (first - owner_.begin()), rows_.begin() + (last - owner_.begin()),
            nullptr);
  held_[static_cast<std::size_t>(held - held_ids_.begin())].release();
  ++removed_keyframes_;
}

std::size_t PlaceIndex::bytes() const {
  std::size_t total = owner_.capacity() * sizeof(int) + rows_.capacity() * sizeof(const uchar*) +
                      held_.capacity() * sizeof(cv::Mat) + held_ids_.capacity() * sizeof(int);
  for (const cv::Mat& held : held_) total += held.total() * held.elemSize();
  for (const Batch& batch : batches_) {
    for (const Table& table : batch.tables) {
      total += table.entries.capacity() * sizeof(Entry) +
               table.starts.capacity() * sizeof(std::uint32_t);
    }
  }
  return total;
}

void PlaceIndex::nearestInBatch(const Batch& batch, const unsigned char* descriptor, int k,
                                std::vector<std::pair<int, std::uint32_t>>& found) const {
  found.clear();
  for (int t = 0; t < kTables; ++t) {
    const Table& table = batch.tables[static_cast<std::size_t>(t)];
    const std::uint32_t key = keyOf(t, descriptor);
    const std::uint32_t prefix = key >> (kKeyBits - kDirectoryBits);
    const auto first = table.entries.begin() + table.starts[prefix];
    const auto last = table.entries.begin() + table.starts[prefix + 1];
    for (auto it = std::lower_bound(first, last, Entry{key, 0}); it != last && it->key == key;
         ++it) {
      if (rows_[it->row] != nullptr) found.emplace_back(0, it->row);
    }
  }
  // A row sharing keys in several tables is one neighbour.
  std::sort(found.begin(), found.end(),
            [](const auto& a, const auto& b) { return a.second < b.second; });
  found.erase(std::unique(found.begin(), found.end(),
                          [](const auto& a, const auto& b) { return a.second == b.second; }),
              found.end());
  for (auto& [distance, row] : found) {
    distance = cv::hal::normHamming(descriptor, rows_[row], kOrbDescriptorBytes);
  }
  const auto kept = std::min(found.size(), static_cast<std::size_t>(std::max(0, k)));
  std::partial_sort(found.begin(), found.begin() + static_cast<std::ptrdiff_t>(kept), found.end());
  found.resize(kept);
}

cv::Mat strongestDescriptors(const FeatureFrame& features, int count) {
  if (features.descriptors.rows <= count) return features.descriptors;
  std::vector<int> order(features.keypoints.size());
  std::iota(order.begin(), order.end(), 0);
  std::partial_sort(order.begin(), order.begin() + count, order.end(), [&](int a, int b) {
    return features.keypoints[static_cast<std::size_t>(a)].response >
           features.keypoints[static_cast<std::size_t>(b)].response;
  });
  cv::Mat out(count, features.descriptors.cols, features.descriptors.type());
  for (int i = 0; i < count; ++i) {
    features.descriptors.row(order[static_cast<std::size_t>(i)]).copyTo(out.row(i));
  }
  return out;
}

std::vector<PlaceCandidate> PlaceIndex::query(const cv::Mat& descriptors,
                                              const PlaceQuery& query) const {
  std::map<int, int> votes;
  if (descriptors.empty() || owner_.empty()) return {};
  const auto allowed = [&](int id) { return query.newest_allowed < 0 || id <= query.newest_allowed; };
  // Per query descriptor, the keyframes it votes for (one vote per keyframe and descriptor).
  std::vector<std::set<int>> voted(static_cast<std::size_t>(descriptors.rows));
  const auto vote = [&](int row, std::size_t descriptor, int distance) {
    const int id = owner_[descriptor];
    if (distance <= query.max_distance && allowed(id) &&
        voted[static_cast<std::size_t>(row)].insert(id).second) {
      ++votes[id];
    }
  };
  std::vector<std::pair<int, std::uint32_t>> found;
  for (const Batch& batch : batches_) {
    if (!allowed(owner_[batch.begin])) break;  // this batch and the later ones are too recent
    for (int row = 0; row < descriptors.rows; ++row) {
      nearestInBatch(batch, descriptors.ptr<uchar>(row), query.neighbours, found);
      for (const auto& [distance, at] : found) vote(row, at, distance);
    }
  }
  // The tail, not yet in a batch: searched one by one when not too recent.
  const std::size_t tail = batches_.empty() ? 0 : batches_.back().end;
  if (tail < owner_.size() && allowed(owner_[tail])) {
    for (int row = 0; row < descriptors.rows; ++row) {
      const uchar* q = descriptors.ptr<uchar>(row);
      for (std::size_t i = tail; i < owner_.size(); ++i) {
        if (!allowed(owner_[i])) break;
        if (rows_[i] == nullptr) continue;
        vote(row, i, cv::hal::normHamming(q, rows_[i], kOrbDescriptorBytes));
      }
    }
  }
  std::vector<PlaceCandidate> out;
  for (const auto& [id, count] : votes) {
    if (count >= query.min_votes) out.push_back({id, count});
  }
  std::sort(out.begin(), out.end(), [](const PlaceCandidate& a, const PlaceCandidate& b) {
    return a.votes != b.votes ? a.votes > b.votes : a.keyframe < b.keyframe;
  });
  if (out.size() > static_cast<std::size_t>(std::max(0, query.max_candidates))) {
    out.resize(static_cast<std::size_t>(std::max(0, query.max_candidates)));
  }
  return out;
}

}  // namespace tessera::fusion
