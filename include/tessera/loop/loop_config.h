#pragma once
// Settings of loop closure (config section loop_closure): place recognition over the tracker's
// keyframes, the geometric check of a revisit, and the pose graph.
#include "tessera/core/config.h"
#include "tessera/fusion/feature_pose.h"

namespace tessera::loop {

struct LoopConfig {
  bool enabled = true;
  // After a tracking restart the new segment sits at a guessed pose (after a relocalisation
  // against an earlier segment, in that segment's frame): its frames are neither fused nor
  // textured until a verified revisit joins it to the first segment. Poses of a segment never
  // joined are left out of the corrected trajectory whatever this says.
  bool hold_apart_unjoined_segments = true;
  // Place recognition: a keyframe is a revisit candidate for a query only when the camera
  // travelled at least this far between them (nearer ones are what odometry already links).
  double min_travel_m = 4.0;
  // Each query descriptor votes for the keyframes among its nearest neighbours closer than
  // this Hamming distance; keyframes with fewer votes are not candidates.
  int max_descriptor_distance = 40;
  int neighbours_per_descriptor = 4;
  int min_votes = 12;
  int candidates_per_query = 2;  // the most voted, checked geometrically in turn
  // The query's strongest descriptors that vote (ORB's response); fewer keep the lookup cheap.
  int query_descriptors = 300;
  // Only every n-th keyframe looks itself up, unless a revisit was verified within the last
  // confirm_within_keyframes keyframes: a revisit lasts many keyframes, so stepping over some
  // finds it as surely, and once found every keyframe follows it up (and confirms it).
  int query_every_n_keyframes = 2;
  // A candidate is checked only if its corrected position lies within the drift bound plus
  // this distance of the query's (two views of one place are a few metres apart at most).
  double max_view_distance_m = 3.0;
  // A revisit's implied correction of the query's pose must stay within what drift could
  // explain: this share of the path travelled between the two keyframes, plus the constants.
  double max_drift_fraction = 0.05;
  double max_drift_m = 0.3;
  double max_drift_deg = 5.0;
  double max_drift_deg_per_m = 0.25;
  // A revisit is accepted only when another query within this many keyframes verifies the
  // same correction (within consistency_m and consistency_deg): one view of a repeated
  // pattern can fake a pose, two views in a row rarely agree on the same wrong one.
  int confirm_within_keyframes = 3;
  double consistency_m = 0.1;
  double consistency_deg = 3.0;
  // Dense refinement of a revisit: point-to-plane ICP on depth taken every dense_stride-th
  // pixel (8: 80 x 60 points of a 640 x 480 frame); accepted when at least min_fitness of the query's points find a partner within
  // icp_distance_m and their rms distance is below max_icp_rmse_m.
  int dense_stride = 8;
  // Depth beyond this is left out of the dense check: a Kinect's noise there (centimetres at
  // 4 m, growing with the square of the distance) would swamp the rms.
  double dense_max_depth_m = 4.0;
  double icp_distance_m = 0.05;
  double min_fitness = 0.3;
  double max_icp_rmse_m = 0.02;
  // Pose graph: loop edges whose line-process weight falls below this are pruned as wrong.
  double edge_prune_threshold = 0.25;
  // The pose graph's nodes: a keyframe every this much path or turn (and each segment start);
  // the keyframes between follow their node rigidly. Chosen when the graph was solved densely
  // (400 keyframes as nodes took 6 s a solve); the sparse solver takes a quarter second for
  // 1,200 nodes.
  double node_spacing_m = 0.5;
  double node_spacing_deg = 15.0;
  // Once closed, a further revisit re-optimises the graph only when the pose it implies for
  // its query differs from the corrected one by more than this (the graph already agrees).
  double reoptimise_m = 0.02;
  // A keyframe within cover_radius_m and cover_angle_deg (corrected poses) of an older kept
  // keyframe of its segment, at least min_travel_m of path behind, revisits that place: it is
  // still a query and a pose, but its features and depth leave memory and it is not indexed,
  // so that memory grows with the places seen rather than with the time spent in them
  // (0: keep every keyframe).
  double cover_radius_m = 0.3;
  double cover_angle_deg = 20.0;
  fusion::FeaturePoseConfig features;  // verification's PnP (config section loop_features)
};

// Overwrites the members present in `section`; throws core::ConfigError on a bad value.
void readConfig(const core::ConfigSection& section, LoopConfig& config);

}  // namespace tessera::loop
