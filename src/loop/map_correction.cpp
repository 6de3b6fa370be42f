#include "tessera/loop/map_correction.h"

#include <algorithm>
#include <iterator>

namespace tessera::loop {

core::Isometry MapCorrection::at(std::int64_t timestamp_ns) const {
  const auto after = std::upper_bound(keyframe_ns.begin(), keyframe_ns.end(), timestamp_ns);
  if (after == keyframe_ns.begin()) return core::Isometry::Identity();
  return motion[static_cast<std::size_t>(std::distance(keyframe_ns.begin(), after) - 1)];
}

bool MapCorrection::inMap(std::int64_t timestamp_ns) const {
  const auto after = std::upper_bound(keyframe_ns.begin(), keyframe_ns.end(), timestamp_ns);
  if (after == keyframe_ns.begin() || in_map.size() != keyframe_ns.size()) return true;
  return in_map[static_cast<std::size_t>(std::distance(keyframe_ns.begin(), after) - 1)];
}

}  // namespace tessera::loop
