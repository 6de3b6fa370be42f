#pragma once
// Loop closure over the tracker's keyframes: each new keyframe is looked up among the earlier
// ones (place recognition), a candidate is checked geometrically (revisit.h), and an accepted
// revisit becomes a loop edge of the pose graph, which is then optimised. The corrected poses
// move every tracked pose with its keyframe.
//
// A revisit is accepted only when (1) the correction it implies is one that drift could
// explain (max_drift_*), and (2) another revisit within a few keyframes implies the same
// correction. The pose graph's line process then prunes loops that still disagree.
//
// Segments: tracking that restarted after a loss starts a segment at a guessed pose, linked to
// the one before by no measurement. Until a revisit joins it to an earlier segment, its
// keyframes look themselves up among every keyframe of the other segments, however near in
// path or far in position, and a revisit across segments is not held to the drift bound (a
// restart's jump is not drift); it is still confirmed by a second one.
//
// Thread-safety: none; loop_closer.h runs it on a worker thread.
#include <cstddef>
#include <memory>
#include <string>
#include <vector>

#include "tessera/core/trajectory.h"
#include "tessera/fusion/place_index.h"
#include "tessera/fusion/tracker.h"
#include "tessera/loop/loop_config.h"
#include "tessera/loop/map_correction.h"
#include "tessera/loop/pose_graph.h"
#include "tessera/loop/revisit.h"

namespace tessera::loop {

struct LoopEdge {
  int match = -1;  // the earlier keyframe
  int query = -1;  // the keyframe that came back to it
  Revisit revisit;
  bool kept = false;   // in the graph after the last optimisation
  bool joins = false;  // between segments not joined before it (no drift bound)
};

struct LoopStats {
  std::size_t keyframes = 0;
  std::size_t candidates_checked = 0;    // place-recognition candidates checked geometrically
  std::size_t revisits_verified = 0;     // of those, the ones features and ICP confirmed
  std::size_t rejected_as_drift = 0;     // implied a correction drift cannot explain
  std::size_t rejected_unconfirmed = 0;  // no second revisit agreed in time
  std::size_t rejected_by_graph = 0;     // pruned by the line process
  std::size_t loop_closures = 0;         // loop edges in the optimised graph
  std::size_t segments = 0;              // tracking segments (1 + restarts)
  std::size_t segments_joined = 0;       // joins of a segment to an earlier one
  // ... of those, where the tracker relocalised against an earlier segment's keyframe
  std::size_t relocalisation_joins = 0;
  std::size_t keyframes_covered = 0;     // revisits of a kept keyframe's place, not kept
  std::size_t optimisations = 0;
  double pose_graph_ms = 0.0;  // all optimisations together
  double keyframe_ms = 0.0;    // all keyframes' work together, optimisations included
  double keyframe_cpu_ms = 0.0;  // ... the CPU time of it (the wall time waits for the CPU)
  double information_ms = 0.0;   // odometry edges' information matrices
  double place_lookup_ms = 0.0;  // place recognition: the lookups
  double place_index_ms = 0.0;   // ... and adding keyframes to the index
  double verification_ms = 0.0;  // geometric checks of candidates
  std::size_t rejected() const {
    return rejected_as_drift + rejected_unconfirmed + rejected_by_graph;
  }
};

class LoopGraph {
 public:
  explicit LoopGraph(const LoopConfig& config);

  // Adds the tracker's next keyframe and closes the loops it finds. Its depth is full size,
  // or already thinned to every dense_stride-th pixel (`depth_thinned`).
  void add(const fusion::KeyframeRecord& record, bool depth_thinned = false);

  const LoopConfig& config() const { return config_; }

  // Re-optimises when loops were added since the last optimisation (end of a run).
  void finish();

  // `trajectory` (tracked poses) moved with the corrections of their keyframes: each pose
  // follows the last keyframe taken at or before it. Poses that follow a keyframe of a segment
  // not joined to the first are left out: they are not in the map's frame.
  core::Trajectory correct(const core::Trajectory& trajectory) const;

  // Each keyframe's motion from its tracked pose to its pose after the last optimisation.
  MapCorrection correction() const;

  const LoopStats& stats() const { return stats_; }
  const std::vector<LoopEdge>& loops() const { return loops_; }
  // Per keyframe, its pose after the last optimisation.
  const std::vector<core::Isometry>& correctedPoses() const { return corrected_; }
  const std::vector<KeyframeView>& keyframes() const { return keyframes_; }
  // Keyframes kept with their features and depth, in the place index: not covered.
  std::size_t keptKeyframes() const { return kept_.size(); }

 private:
  // A verified revisit within the confirmation window.
  struct Pending {
    int query = -1;
    int match = -1;
    Revisit revisit;
    bool accepted = false;  // confirmed, and a loop edge
    bool joins = false;     // across segments not yet joined
  };
  // The pose of `query` that `revisit` from `match` implies, from match's corrected pose.
  core::Isometry impliedPose(int match, int query, const Revisit& revisit) const;
  double travelBetween(int match, int query) const;  // camera path between the two, as tracked
  // The largest correction of the query's position a loop from `match` may make (max_drift_*).
  double driftBound(int match, int query) const;
  bool withinDrift(int match, int query, const Revisit& revisit) const;
  // Whether the two keyframes' corrected positions are near enough to see one place.
  bool withinView(int match, int query) const;
  bool agree(const Pending& a, const Pending& b) const;
  // Segments, joined ones sharing a root (union-find over segment ids).
  int rootOf(int keyframe) const;
  bool joinedToFirst(int keyframe) const;
  // Joins the two keyframes' segments, the newer under the older so that the root stays the
  // oldest. Whether they were apart.
  bool joinSegments(int keyframe_a, int keyframe_b);
  double seconds(int keyframe) const;  // its time stamp, for messages
  // The newest keyframe of a segment not joined to `query`'s, or -1.
  int newestOfAnotherSegment(int query) const;
  void acceptLoop(const Pending& loop);
  // A segment the tracker began by relocalising against the keyframe at `against_ns`: joined
  // to that keyframe's when the pair is verified as a revisit is, and the revisit's pose agrees
  // with the tracker's (consistency_m, consistency_deg). Whether it was.
  bool joinRelocalised(int query, std::int64_t against_ns);
  // Whether `query` lies where an older kept keyframe of its segment already stands.
  bool coveredByOlder(int query) const;
  // Lets a covered keyframe's features and depth go.
  void release(KeyframeView& key);
  void optimise();

  LoopConfig config_;
  fusion::PlaceIndex index_;
  std::vector<KeyframeView> keyframes_;
  std::vector<core::Isometry> corrected_;
  // The graph's nodes (keyframe ids, ascending), each keyframe's node (the last at or before
  // it) and the odometry edges between consecutive nodes.
  std::vector<int> nodes_;
  std::vector<std::size_t> node_of_;
  std::vector<GraphEdge> odometry_;
  std::vector<LoopEdge> loops_;
  std::vector<Pending> pending_;
  std::vector<int> kept_;            // keyframes not covered (indexed), ascending
  std::vector<int> segment_of_;      // per keyframe
  std::vector<int> segment_start_;   // per segment, its first keyframe
  std::vector<int> segment_parent_;  // per segment, union-find parent
  // ... as the segment began (itself, or the first when found in a continued map); the loops
  // kept join them from there after each optimisation.
  std::vector<int> segment_start_parent_;
  int last_revisit_query_ = -1;  // the last keyframe whose lookup verified a revisit
  bool last_revisit_accepted_ = false;  // ... and whether it was confirmed
  bool dirty_ = false;  // loops added since the last optimisation
  LoopStats stats_;
};

}  // namespace tessera::loop
