#pragma once
// The transforms a bag's tf (or pose) topic carries, by child frame, to look up a camera's
// pose in the world frame at any time: each link of the chain from the camera up to the world
// is interpolated at that time and the links are composed.
#include <cstdint>
#include <map>
#include <optional>
#include <string>

#include "tessera/core/pose.h"
#include "tessera/core/trajectory.h"

namespace tessera::drivers::ros1 {

class TransformTree {
 public:
  // T_parent_child at t_ns; a static link (from /tf_static) holds at every time. A frame keeps
  // the first parent it is given (tf allows one).
  void add(const std::string& parent, const std::string& child, std::int64_t t_ns,
           const core::Isometry& T_parent_child, bool is_static);

  // T_world_frame at t_ns; nothing when the chain is broken or a moving link has no samples
  // within max_gap_ns either side of t_ns.
  std::optional<core::Isometry> lookup(const std::string& world, const std::string& frame,
                                       std::int64_t t_ns,
                                       std::int64_t max_gap_ns = 200'000'000) const;

  bool empty() const { return links_.empty(); }

  // tf1 bags write "/world"; tf2 writes "world".
  static std::string normalised(const std::string& frame);

 private:
  struct Link {
    std::string parent;
    core::Trajectory poses;  // T_parent_child by time
    bool is_static = false;
  };
  std::map<std::string, Link> links_;  // by child frame
};

}  // namespace tessera::drivers::ros1
