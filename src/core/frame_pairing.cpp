#include "tessera/core/frame_pairing.h"

#include <algorithm>
#include <cstdlib>
#include <iterator>

namespace tessera::core {

void PairingInbox::pushDepth(CapturedImage frame, std::size_t missed) {
  delivered += missed + 1;
  dropped += missed;
  depth.push_back(std::move(frame));
  while (depth.size() > depth_capacity) {
    depth.pop_front();
    ++dropped;
  }
  changed.notify_all();
}

void PairingInbox::pushColour(CapturedImage frame) {
  // In stamp order (a recorder or a network may hand colour images over out of order, and
  // pairing drops every image older than the one it takes); in order, this is a push_back.
  const auto at =
      std::upper_bound(colour.begin(), colour.end(), frame.stamp,
                       [](std::int64_t stamp, const CapturedImage& c) { return stamp < c.stamp; });
  colour.insert(at, std::move(frame));
  colour_started = true;
  while (colour.size() > colour_capacity) colour.pop_front();
  changed.notify_all();
}

LiveStats PairingInbox::withCounts(LiveStats stats) {
  std::lock_guard lock(mutex);
  stats.frames_delivered = delivered;
  stats.frames_dropped = dropped;
  return stats;
}

void PairingInbox::clearFrames() {
  depth.clear();
  colour.clear();
  colour_started = false;
}

std::chrono::microseconds PairingInbox::colourWait(std::chrono::microseconds usual) const {
  return colour_started ? usual : std::max(usual, colour_start_wait);
}

std::optional<CapturedImage> PairingInbox::takeColourNear(std::unique_lock<std::mutex>& lock,
                                                          std::int64_t stamp,
                                                          std::int64_t tolerance,
                                                          std::chrono::microseconds wait) {
  changed.wait_for(lock, wait, [&] {
    return lost || (!colour.empty() && colour.back().stamp + tolerance >= stamp);
  });
  const auto distance = [&](const CapturedImage& c) { return std::llabs(c.stamp - stamp); };
  const auto nearest = std::min_element(
      colour.begin(), colour.end(),
      [&](const CapturedImage& a, const CapturedImage& b) { return distance(a) < distance(b); });
  if (nearest == colour.end() || distance(*nearest) > tolerance) return std::nullopt;
  CapturedImage taken = std::move(*nearest);
  colour.erase(colour.begin(), std::next(nearest));
  return taken;
}

}  // namespace tessera::core
