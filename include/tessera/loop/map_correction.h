#pragma once
// What loop closure tells the map: after each pose-graph optimisation, how far each keyframe's
// pose moved (corrected * tracked^-1, a rigid motion of the world). A pose, or a patch placed
// from it, follows the last keyframe taken at or before its time, as LoopGraph::correct does;
// one newer than every keyframe of the correction follows the newest (what came after it is
// odometry, which the optimisation did not change).
#include <cstddef>
#include <cstdint>
#include <vector>

#include "tessera/core/pose.h"

namespace tessera::loop {

struct MapCorrection {
  std::size_t generation = 0;  // the optimisations it follows (1 after the first)
  // Keyframe times, ascending, and each keyframe's motion.
  std::vector<std::int64_t> keyframe_ns;
  std::vector<core::Isometry> motion;
  // Per keyframe, whether its tracking segment is joined to the first one (LoopGraph): a
  // segment begun by a tracking restart sits at a guessed pose until a verified revisit joins it.
  std::vector<bool> in_map;

  // The motion of whatever was placed from a pose at `timestamp_ns`; identity before the first
  // keyframe.
  core::Isometry at(std::int64_t timestamp_ns) const;
  // Whether a pose at `timestamp_ns` is in the map's frame: its keyframe's segment is joined to
  // the first (true before the first keyframe, and without segment information).
  bool inMap(std::int64_t timestamp_ns) const;
};

}  // namespace tessera::loop
