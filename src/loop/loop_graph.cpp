#include "tessera/loop/loop_graph.h"

#include <algorithm>
#include <chrono>
#include <numeric>

#include <spdlog/spdlog.h>

#include "tessera/core/cpu_time.h"

namespace tessera::loop {

namespace {

double msSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

// Odometry across a tracking restart says nothing about the motion: the edge is kept only so
// that the graph stays connected, with this weight.
constexpr double kRestartEdgeWeight = 1e-6;

double translationBetween(const core::Isometry& a, const core::Isometry& b) {
  return (a.translation() - b.translation()).norm();
}

}  // namespace

LoopGraph::LoopGraph(const LoopConfig& config) : config_(config) {}

core::Isometry LoopGraph::impliedPose(int match, int /*query*/, const Revisit& revisit) const {
  return corrected_[static_cast<std::size_t>(match)] * revisit.T_query_match.inverse();
}

double LoopGraph::travelBetween(int match, int query) const {
  return keyframes_[static_cast<std::size_t>(query)].travel_m -
         keyframes_[static_cast<std::size_t>(match)].travel_m;
}

double LoopGraph::driftBound(int match, int query) const {
  return config_.max_drift_m + config_.max_drift_fraction * travelBetween(match, query);
}

bool LoopGraph::withinDrift(int match, int query, const Revisit& revisit) const {
  const double travel = travelBetween(match, query);
  const core::Isometry implied = impliedPose(match, query, revisit);
  const core::Isometry& now = corrected_[static_cast<std::size_t>(query)];
  return translationBetween(implied, now) <= driftBound(match, query) &&
         core::rotationAngleDeg(now.inverse() * implied) <=
             config_.max_drift_deg + config_.max_drift_deg_per_m * travel;
}

bool LoopGraph::withinView(int match, int query) const {
  return translationBetween(corrected_[static_cast<std::size_t>(match)],
                            corrected_[static_cast<std::size_t>(query)]) <=
         config_.max_view_distance_m + driftBound(match, query);
}

bool LoopGraph::agree(const Pending& a, const Pending& b) const {
  // Odometry links the two queries only within a segment (or segments already joined), and
  // two joins confirm each other only when they join the same segments.
  if (rootOf(a.query) != rootOf(b.query)) return false;
  if (a.joins != b.joins || (a.joins && rootOf(a.match) != rootOf(b.match))) return false;
  // The motion between the two queries as the two loops imply it, against odometry's.
  const core::Isometry via_loops =
      impliedPose(a.match, a.query, a.revisit).inverse() * impliedPose(b.match, b.query, b.revisit);
  const core::Isometry via_odometry = corrected_[static_cast<std::size_t>(a.query)].inverse() *
                                      corrected_[static_cast<std::size_t>(b.query)];
  const core::Isometry difference = via_odometry.inverse() * via_loops;
  return difference.translation().norm() <= config_.consistency_m &&
         core::rotationAngleDeg(difference) <= config_.consistency_deg;
}

int LoopGraph::rootOf(int keyframe) const {
  int segment = segment_of_[static_cast<std::size_t>(keyframe)];
  while (segment_parent_[static_cast<std::size_t>(segment)] != segment) {
    segment = segment_parent_[static_cast<std::size_t>(segment)];
  }
  return segment;
}

bool LoopGraph::joinedToFirst(int keyframe) const { return rootOf(keyframe) == rootOf(0); }

bool LoopGraph::joinSegments(int keyframe_a, int keyframe_b) {
  const int root_a = rootOf(keyframe_a), root_b = rootOf(keyframe_b);
  if (root_a == root_b) return false;
  segment_parent_[static_cast<std::size_t>(std::max(root_a, root_b))] = std::min(root_a, root_b);
  return true;
}

double LoopGraph::seconds(int keyframe) const {
  return 1e-9 * static_cast<double>(keyframes_[static_cast<std::size_t>(keyframe)].timestamp_ns);
}

int LoopGraph::newestOfAnotherSegment(int query) const {
  const int root = rootOf(query);
  for (int segment = segment_of_[static_cast<std::size_t>(query)]; segment-- > 0;) {
    const int last = segment_start_[static_cast<std::size_t>(segment) + 1] - 1;
    if (rootOf(last) != root) return last;
  }
  return -1;
}

void LoopGraph::add(const fusion::KeyframeRecord& record, bool depth_thinned) {
  const auto start = std::chrono::steady_clock::now();
  const double cpu_start_s = core::threadCpuSeconds();
  KeyframeView key;
  key.id = static_cast<int>(keyframes_.size());
  key.timestamp_ns = record.timestamp_ns;
  key.T_W_C = record.T_W_C;
  key.features = record.features;
  key.intrinsics = record.intrinsics;
  key.depth_m = depth_thinned ? record.depth_m : strideDepth(record.depth_m, config_.dense_stride);
  key.starts_segment = record.starts_segment || keyframes_.empty();
  if (keyframes_.empty()) {
    corrected_.push_back(record.T_W_C);
  } else {
    const KeyframeView& previous = keyframes_.back();
    const core::Isometry step = previous.T_W_C.inverse() * record.T_W_C;  // previous <- key
    key.travel_m = previous.travel_m + (key.starts_segment ? 0.0 : step.translation().norm());
    corrected_.push_back(corrected_.back() * step);
  }
  // A new node after enough path or turn since the last one, and at each segment start.
  bool node = nodes_.empty() || key.starts_segment;
  if (!node) {
    const KeyframeView& last = keyframes_[static_cast<std::size_t>(nodes_.back())];
    node = key.travel_m - last.travel_m >= config_.node_spacing_m ||
           core::rotationAngleDeg(last.T_W_C.inverse() * key.T_W_C) >= config_.node_spacing_deg;
  }
  if (node && !nodes_.empty()) {
    KeyframeView& last = keyframes_[static_cast<std::size_t>(nodes_.back())];
    GraphEdge edge;
    edge.source = static_cast<int>(nodes_.size()) - 1;
    edge.target = static_cast<int>(nodes_.size());
    edge.T_target_source = key.T_W_C.inverse() * last.T_W_C;
    edge.information = key.starts_segment
                           ? Matrix6d(Matrix6d::Identity() * kRestartEdgeWeight)
                           : edgeInformation(last, key, edge.T_target_source, config_);
    odometry_.push_back(edge);
    stats_.information_ms += msSince(start);
    // A covered node kept its depth for this edge only.
    if (last.covered) release(last);
  }
  if (key.starts_segment) {
    const int segment = static_cast<int>(segment_start_.size());
    segment_start_.push_back(key.id);
    // Found in a continued map, the segment is in the map's frame: the first segment's.
    segment_parent_.push_back(record.found_in_continued_map && segment > 0 ? 0 : segment);
    segment_start_parent_.push_back(segment_parent_.back());
    stats_.segments = segment_start_.size();
  }
  segment_of_.push_back(static_cast<int>(segment_start_.size()) - 1);
  if (node) nodes_.push_back(key.id);
  node_of_.push_back(nodes_.size() - 1);
  keyframes_.push_back(std::move(key));
  const KeyframeView& query = keyframes_.back();
  if (query.starts_segment && record.relocalised_against_ns) {
    joinRelocalised(query.id, *record.relocalised_against_ns);
  }

  // Candidates: keyframes at least min_travel_m of path behind.
  const auto last_far = std::upper_bound(
      keyframes_.begin(), keyframes_.end(), query.travel_m - config_.min_travel_m,
      [](double travel, const KeyframeView& k) { return travel < k.travel_m; });
  fusion::PlaceQuery place;
  place.max_distance = config_.max_descriptor_distance;
  place.neighbours = config_.neighbours_per_descriptor;
  place.min_votes = config_.min_votes;
  place.max_candidates = config_.candidates_per_query;
  // ... or any keyframe of a segment not joined to the query's: odometry does not link them.
  const int unjoined = newestOfAnotherSegment(query.id);
  place.newest_allowed = std::max(static_cast<int>(last_far - keyframes_.begin()) - 1, unjoined);
  const auto lookup_start = std::chrono::steady_clock::now();
  std::vector<fusion::PlaceCandidate> candidates;
  // A revisit waiting for another to confirm it is followed up at every keyframe; once
  // confirmed, the walk through a known place looks itself up at the usual cadence (each
  // revisit found then is confirmed by the accepted one before it).
  const bool following_revisit = last_revisit_query_ >= 0 && !last_revisit_accepted_ &&
                                 query.id - last_revisit_query_ <= config_.confirm_within_keyframes;
  // A segment not joined to the first looks itself up at every keyframe until it is.
  const bool adrift = !joinedToFirst(query.id);
  const bool lookup =
      following_revisit || adrift || query.id % config_.query_every_n_keyframes == 0;
  if (lookup && place.newest_allowed >= 0) {
    candidates = index_.query(
        fusion::strongestDescriptors(*query.features, config_.query_descriptors), place);
  }
  stats_.place_lookup_ms += msSince(lookup_start);
  // A revisit still looks itself up (above) but does not stand for its place: the older
  // keyframe there does.
  keyframes_.back().covered = coveredByOlder(query.id);
  if (query.covered) {
    ++stats_.keyframes_covered;
  } else {
    const auto index_start = std::chrono::steady_clock::now();
    index_.add(query.id, query.features->descriptors);
    kept_.push_back(query.id);
    stats_.place_index_ms += msSince(index_start);
  }

  for (const fusion::PlaceCandidate& candidate : candidates) {
    const bool joins = rootOf(candidate.keyframe) != rootOf(query.id);
    if (!joins && !withinView(candidate.keyframe, query.id)) continue;
    ++stats_.candidates_checked;
    std::string why;
    const auto verify_start = std::chrono::steady_clock::now();
    const auto revisit =
        verifyRevisit(keyframes_[static_cast<std::size_t>(candidate.keyframe)], query, config_, why);
    stats_.verification_ms += msSince(verify_start);
    if (!revisit) {
      spdlog::debug("loop: keyframe {} -> {}{} not verified: {}", query.id, candidate.keyframe,
                    joins ? " (across segments)" : "", why);
      continue;
    }
    ++stats_.revisits_verified;
    last_revisit_query_ = query.id;
    last_revisit_accepted_ = false;
    if (!joins && !withinDrift(candidate.keyframe, query.id, *revisit)) {
      ++stats_.rejected_as_drift;
      spdlog::debug("loop: keyframe {} -> {} rejected: more correction than drift explains",
                         query.id, candidate.keyframe);
      continue;
    }
    // Accepted when an earlier revisit in the window agrees; accepted revisits stay in the
    // window so that the next ones can be confirmed by them.
    Pending loop{query.id, candidate.keyframe, *revisit, false, joins};
    for (Pending& earlier : pending_) {
      if (earlier.query == query.id || !agree(earlier, loop)) continue;
      if (!earlier.accepted) acceptLoop(earlier);
      earlier.accepted = true;
      loop.accepted = true;
    }
    if (loop.accepted) acceptLoop(loop);
    last_revisit_accepted_ = loop.accepted;
    pending_.push_back(loop);
    break;  // one revisit per keyframe
  }
  // Revisits that left the window: those never confirmed are rejected.
  const auto expired = [&](const Pending& p) {
    return query.id - p.query > config_.confirm_within_keyframes;
  };
  for (const Pending& p : pending_) {
    if (expired(p) && !p.accepted) ++stats_.rejected_unconfirmed;
  }
  pending_.erase(std::remove_if(pending_.begin(), pending_.end(), expired), pending_.end());
  // The newest node keeps its depth for the odometry edge to the next node.
  if (query.covered && nodes_.back() != query.id) release(keyframes_.back());
  ++stats_.keyframes;
  if (dirty_) optimise();
  stats_.keyframe_ms += msSince(start);
  stats_.keyframe_cpu_ms += 1e3 * (core::threadCpuSeconds() - cpu_start_s);
}

bool LoopGraph::joinRelocalised(int query, std::int64_t against_ns) {
  const auto older =
      std::lower_bound(keyframes_.begin(), keyframes_.end(), against_ns,
                       [](const KeyframeView& k, std::int64_t t) { return k.timestamp_ns < t; });
  // Not one of this graph's keyframes (a continued map's), or its depth is gone (covered).
  if (older == keyframes_.end() || older->timestamp_ns != against_ns || older->depth_m.empty()) {
    return false;
  }
  const int match = static_cast<int>(older - keyframes_.begin());
  if (rootOf(match) == rootOf(query)) return false;
  const KeyframeView& key = keyframes_[static_cast<std::size_t>(query)];
  ++stats_.candidates_checked;
  std::string why;
  const auto verify_start = std::chrono::steady_clock::now();
  const auto revisit = verifyRevisit(*older, key, config_, why);
  stats_.verification_ms += msSince(verify_start);
  if (!revisit) {
    spdlog::debug("loop: keyframe {} -> {} (relocalised there) not verified: {}", query, match,
                  why);
    return false;
  }
  ++stats_.revisits_verified;
  // The tracker's relative pose of the two (both tracked poses) against the revisit's.
  const core::Isometry tracker = key.T_W_C.inverse() * older->T_W_C;
  const core::Isometry difference = tracker.inverse() * revisit->T_query_match;
  if (difference.translation().norm() > config_.consistency_m ||
      core::rotationAngleDeg(difference) > config_.consistency_deg) {
    spdlog::debug(
        "loop: keyframe {} -> {} (relocalised there): the revisit and the tracker "
        "disagree by {:.0f} mm",
        query, match, 1e3 * difference.translation().norm());
    return false;
  }
  acceptLoop(Pending{query, match, *revisit, true, true});
  last_revisit_query_ = query;
  last_revisit_accepted_ = true;
  ++stats_.relocalisation_joins;
  return true;
}

bool LoopGraph::coveredByOlder(int query) const {
  if (config_.cover_radius_m <= 0.0) return false;
  const core::Isometry& at = corrected_[static_cast<std::size_t>(query)];
  const double travel = keyframes_[static_cast<std::size_t>(query)].travel_m;
  for (const int kept : kept_) {
    const KeyframeView& older = keyframes_[static_cast<std::size_t>(kept)];
    // Kept keyframes ascend in travel: the rest are too recent to be a revisit.
    if (travel - older.travel_m < config_.min_travel_m) break;
    if (rootOf(kept) != rootOf(query)) continue;
    if (core::posesNear(corrected_[static_cast<std::size_t>(kept)], at, config_.cover_radius_m,
                        config_.cover_angle_deg)) {
      return true;
    }
  }
  return false;
}

void LoopGraph::release(KeyframeView& key) {
  key.features = std::make_shared<const fusion::FeatureFrame>();
  key.depth_m.release();
}

void LoopGraph::acceptLoop(const Pending& loop) {
  const core::Isometry implied = impliedPose(loop.match, loop.query, loop.revisit);
  const core::Isometry& now = corrected_[static_cast<std::size_t>(loop.query)];
  // The graph is re-optimised when this loop pulls its query away from where it is now.
  if (stats_.optimisations == 0 || translationBetween(implied, now) > config_.reoptimise_m) {
    dirty_ = true;
  }
  loops_.push_back({loop.match, loop.query, loop.revisit, false, loop.joins});
  if (joinSegments(loop.query, loop.match)) {
    // A join is re-optimised whatever it moves, so that a correction saying it is published
    // (the integration stage holds the segment apart until one does).
    dirty_ = true;
    ++stats_.segments_joined;
    spdlog::info("loop: keyframe {} ({:.3f} s) joins its segment to keyframe {}'s ({:.3f} s){}",
                 loop.query, seconds(loop.query), loop.match, seconds(loop.match),
                 joinedToFirst(loop.query) ? ": both are in the map now" : "");
  }
}

void LoopGraph::finish() {
  for (const Pending& p : pending_) {
    if (!p.accepted) ++stats_.rejected_unconfirmed;
  }
  pending_.clear();
  const bool unsolved = std::any_of(loops_.begin(), loops_.end(),
                                    [](const LoopEdge& loop) { return !loop.kept; });
  if (dirty_ || unsolved) optimise();
}

void LoopGraph::optimise() {
  // Node poses as tracked; a loop between two keyframes becomes an edge between their nodes,
  // carried over by the tracked motion from each node to its keyframe.
  const auto nodePose = [&](int keyframe) -> const core::Isometry& {
    const int node = nodes_[node_of_[static_cast<std::size_t>(keyframe)]];
    return keyframes_[static_cast<std::size_t>(node)].T_W_C;
  };
  const auto keyPose = [&](int keyframe) -> const core::Isometry& {
    return keyframes_[static_cast<std::size_t>(keyframe)].T_W_C;
  };
  std::vector<GraphEdge> edges = odometry_;
  for (const LoopEdge& loop : loops_) {
    GraphEdge edge;
    edge.source = static_cast<int>(node_of_[static_cast<std::size_t>(loop.match)]);
    edge.target = static_cast<int>(node_of_[static_cast<std::size_t>(loop.query)]);
    edge.T_target_source = nodePose(loop.query).inverse() * keyPose(loop.query) *
                           loop.revisit.T_query_match * keyPose(loop.match).inverse() *
                           nodePose(loop.match);
    edge.information = loop.revisit.information;
    edge.loop = true;
    edges.push_back(edge);
  }
  // From the tracked poses each time, so that a pruned loop leaves no trace.
  std::vector<core::Isometry> initial;
  initial.reserve(nodes_.size());
  for (const int node : nodes_) initial.push_back(keyPose(node));
  // The largest correction any loop may make (its drift bound) sizes the first solve.
  double drift_distance_m = 0.0;
  for (const LoopEdge& loop : loops_) {
    drift_distance_m = std::max(drift_distance_m, driftBound(loop.match, loop.query));
    if (loop.joins) {
      // A join moves its segment by the restart's jump, whatever the drift bound.
      const core::Isometry implied = keyPose(loop.match) * loop.revisit.T_query_match.inverse();
      drift_distance_m =
          std::max(drift_distance_m, translationBetween(implied, keyPose(loop.query)));
    }
  }
  const GraphSolution solution =
      optimisePoseGraph(initial, edges, config_.edge_prune_threshold, drift_distance_m);
  ++stats_.optimisations;
  stats_.pose_graph_ms += solution.ms;
  for (std::size_t k = 0; k < keyframes_.size(); ++k) {
    const std::size_t node = node_of_[k];
    corrected_[k] = solution.T_W_C[node] * keyPose(nodes_[node]).inverse() * keyframes_[k].T_W_C;
  }
  std::vector<LoopEdge> kept;
  for (std::size_t i = 0; i < loops_.size(); ++i) {
    if (solution.loop_kept[i]) {
      loops_[i].kept = true;
      kept.push_back(loops_[i]);
    } else {
      ++stats_.rejected_by_graph;
      spdlog::info("loop: keyframe {} -> {} pruned by the pose graph", loops_[i].query,
                   loops_[i].match);
    }
  }
  loops_ = std::move(kept);
  stats_.loop_closures = loops_.size();
  // Segments are joined by the loops kept: a join the graph pruned joins nothing.
  segment_parent_ = segment_start_parent_;
  for (const LoopEdge& loop : loops_) joinSegments(loop.query, loop.match);
  stats_.segments_joined = 0;
  for (std::size_t s = 0; s < segment_parent_.size(); ++s) {
    stats_.segments_joined += segment_parent_[s] != static_cast<int>(s) ? 1 : 0;
  }
  dirty_ = false;
}

MapCorrection LoopGraph::correction() const {
  MapCorrection correction;
  correction.generation = stats_.optimisations;
  correction.keyframe_ns.reserve(keyframes_.size());
  correction.motion.reserve(keyframes_.size());
  correction.in_map.reserve(keyframes_.size());
  for (std::size_t k = 0; k < keyframes_.size(); ++k) {
    correction.keyframe_ns.push_back(keyframes_[k].timestamp_ns);
    correction.motion.push_back(corrected_[k] * keyframes_[k].T_W_C.inverse());
    correction.in_map.push_back(joinedToFirst(static_cast<int>(k)));
  }
  return correction;
}

core::Trajectory LoopGraph::correct(const core::Trajectory& trajectory) const {
  core::Trajectory out;
  std::size_t anchor = 0;
  for (const auto& [timestamp_ns, T_W_C] : trajectory) {
    while (anchor + 1 < keyframes_.size() && keyframes_[anchor + 1].timestamp_ns <= timestamp_ns) {
      ++anchor;
    }
    if (keyframes_.empty()) {
      out[timestamp_ns] = T_W_C;
      continue;
    }
    // A pose of a segment never joined is at the guess its restart made: not in the map.
    if (!joinedToFirst(static_cast<int>(anchor))) continue;
    out[timestamp_ns] = corrected_[anchor] * keyframes_[anchor].T_W_C.inverse() * T_W_C;
  }
  return out;
}

}  // namespace tessera::loop
