#include "internal/transform_tree.h"

namespace tessera::drivers::ros1 {

std::string TransformTree::normalised(const std::string& frame) {
  return !frame.empty() && frame.front() == '/' ? frame.substr(1) : frame;
}

void TransformTree::add(const std::string& parent, const std::string& child, std::int64_t t_ns,
                        const core::Isometry& T_parent_child, bool is_static) {
  Link& link = links_[normalised(child)];
  if (link.parent.empty()) link.parent = normalised(parent);
  if (link.parent != normalised(parent)) return;
  link.is_static = link.is_static || is_static;
  link.poses[t_ns] = T_parent_child;
}

std::optional<core::Isometry> TransformTree::lookup(const std::string& world,
                                                    const std::string& frame, std::int64_t t_ns,
                                                    std::int64_t max_gap_ns) const {
  const std::string root = normalised(world);
  std::string at = normalised(frame);
  core::Isometry T_at_frame = core::Isometry::Identity();
  for (std::size_t depth = 0; at != root; ++depth) {
    const auto it = links_.find(at);
    if (it == links_.end() || depth > links_.size()) return std::nullopt;
    const Link& link = it->second;
    std::optional<core::Isometry> T_parent_at;
    if (link.is_static) {
      T_parent_at = link.poses.rbegin()->second;
    } else {
      T_parent_at = core::poseAt(link.poses, t_ns, max_gap_ns);
    }
    if (!T_parent_at) return std::nullopt;
    T_at_frame = *T_parent_at * T_at_frame;
    at = link.parent;
  }
  return T_at_frame;
}

}  // namespace tessera::drivers::ros1
