#pragma once
// Camera tracking: RGB-D odometry (OpenCV's RgbdICPOdometry: photometric and point-to-plane ICP
// terms over a coarse-to-fine pyramid) of each frame against a keyframe, started from a
// constant-velocity guess. Across large motions (a gap in time, a failed solve) the guess
// comes from features (ORB, 3D-2D PnP against the keyframe); after a loss or an interrupted
// source the frame is relocalised against recent keyframes, then against every keyframe so far
// (found through a place index), before tracking goes on.
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "tessera/core/config.h"
#include "tessera/core/frame.h"
#include "tessera/fusion/feature_pose.h"

namespace tessera::fusion {

struct TrackerConfig {
  double min_depth_m = 0.3;
  double max_depth_m = 4.0;
  double max_depth_difference_m = 0.07;  // correspondences farther apart in depth are dropped
  // A solve that moves the pose farther than this from the motion guess (per frame interval)
  // is a tracking loss.
  double max_translation_m = 0.15;
  double max_rotation_deg = 15.0;
  int lost_frames_before_restart = 10;  // then tracking restarts from the current frame
  // Gauss-Newton iterations per pyramid level, finest level first; the level count follows.
  // {2, 3, 4} lost the loop scene's corridor at its start; {4, 4, 6} tracks it (docs/SCENES.md).
  std::vector<int> iterations_per_level = {4, 4, 6};
  // Odometry runs on blocks of N x N pixels: 2 tracks 640x480 frames at 320x240, a quarter of
  // the work (grey and depth averaged over each block, depth not across an edge).
  int tracking_scale = 2;
  // Frames are tracked against a keyframe until the camera is this far from it; then the
  // frame just tracked becomes the keyframe.
  double keyframe_translation_m = 0.10;
  double keyframe_rotation_deg = 10.0;
  // Start each solve from the last frame-to-frame motion, stretched over the time since the
  // last tracked frame (constant velocity), rather than from no motion.
  bool constant_velocity = true;
  // A frame taken more than this after the last tracked one (frames dropped, a keyframe
  // recording) is first posed from features, then refined densely, seconds.
  double feature_gap_s = 0.05;
  // Keyframes kept (with their images, for a dense refinement) to relocalise against after a
  // loss or a reconnect.
  int relocalisation_keyframes = 10;
  // When none of those gives a pose: look the frame up among every keyframe so far (their
  // features, in a place index) and take the feature pose of the first candidate that gives
  // one. The frame then starts a segment, which loop closure joins to the old keyframe's.
  bool relocalise_against_all_keyframes = true;
  int relocalisation_candidates = 3;  // the most voted keyframes tried, in turn
  int relocalisation_min_votes = 12;  // descriptors near a keyframe's for it to be one
  // A new keyframe within this distance and turn (tracked poses) of an older one kept for that
  // lookup revisits its place and is not kept for it: memory grows with the places seen, not
  // with the time spent in them (0: keep every keyframe). A run that closes loops leaves this
  // to loop closure (Tracker::leaveCoverToLoopClosure).
  double relocalisation_cover_radius_m = 0.3;
  double relocalisation_cover_angle_deg = 20.0;
  FeaturePoseConfig features;  // config section tracker_features
};

void readConfig(const core::ConfigSection& section, TrackerConfig& config);

// kRelocalised: found again after a loss or a source interruption, against a recent keyframe,
// or against an older one; a new segment starts at the pose it gives when that keyframe is an
// older one, or one made before the last restart.
// kRestarted: not found again; a new segment starts at the last good pose.
enum class TrackingStatus { kFirst, kTracked, kLost, kRelocalised, kRestarted };

// A keyframe as the tracker made it, for place recognition and the pose graph (loop closure):
// its pose as tracked, its features, and its depth in metres (NaN where missing).
struct KeyframeRecord {
  std::int64_t timestamp_ns = 0;
  core::Isometry T_W_C = core::Isometry::Identity();
  SharedFeatures features = std::make_shared<const FeatureFrame>();
  cv::Mat depth_m;  // CV_32FC1 at the frame's size; shared with the tracker, not to be written
  core::Intrinsics intrinsics;
  // Tracking restarted here after a loss, or was relocalised against an old keyframe: its pose
  // does not follow from the keyframe before by odometry.
  bool starts_segment = false;
  // Relocalised against this older keyframe (its time): its pose was found in that keyframe's
  // segment, and loop closure joins the two once it verifies the pair.
  std::optional<std::int64_t> relocalised_against_ns;
  // Relocalised against a continued map's keyframe (`tessera run --continue`): the pose is in
  // the map's frame, though loop closure, which has this session's keyframes only, cannot
  // verify it.
  bool found_in_continued_map = false;
  // Kept among the keyframes relocalised against (relocalise_against_all_keyframes): a later
  // session that continues the map relocalises against it too.
  bool relocalisation = false;
};

struct TrackingResult {
  TrackingStatus status = TrackingStatus::kFirst;
  core::Isometry T_W_C = core::Isometry::Identity();  // valid unless kLost
  bool from_features = false;                         // the solve started from a feature pose
  bool relocalised_globally = false;  // kRelocalised against a keyframe older than the recent
  std::string problem;                                // why tracking was lost
  // Keyframes made while tracking this frame (the last tracked frame may become one too).
  std::vector<std::shared_ptr<const KeyframeRecord>> new_keyframes;
};

// A keyframe of a map as the tracker relocalises against it: its time, pose and features.
// What a later session that continues the map (`tessera run --continue`) starts from.
struct MapKeyframe {
  std::int64_t timestamp_ns = 0;
  core::Isometry T_W_C = core::Isometry::Identity();
  SharedFeatures features = std::make_shared<const FeatureFrame>();
};

// Not thread-safe: owned by the fusion stage, which runs serially.
class Tracker {
 public:
  explicit Tracker(const TrackerConfig& config);
  ~Tracker();

  // The pose of `frame`. The first frame (and a restart) gets `initial_T_W_C`.
  TrackingResult track(const core::Frame& frame, const core::Isometry& initial_T_W_C);

  // The source was interrupted (a device lost and reconnected): the camera may have moved
  // meanwhile, so the next frame is relocalised rather than tracked from the last pose.
  void sourceInterrupted();

  // Starts in an earlier session's map: its keyframes join those relocalised against, and the
  // first frames are relocalised against them rather than started at initial_T_W_C. Until one
  // is found they are lost; after lost_frames_before_restart of them the session starts in its
  // own frame at initial_T_W_C, and TrackingResult::problem says so. Call before track().
  void continueMap(const std::vector<MapKeyframe>& keyframes);

  // Loop closure decides which keyframes revisit a kept one's place, at poses it corrected:
  // a revisit's tracked pose has drifted too far from the first visit's for the tracker's own
  // test (relocalisation_cover_radius_m). Every keyframe is then kept for relocalisation until
  // forgetKeyframes() names it. Call before track().
  void leaveCoverToLoopClosure();
  // Drops the keyframes of this session taken at these times from those relocalised against
  // (features and place index); returns how many it dropped.
  std::size_t forgetKeyframes(const std::vector<std::int64_t>& timestamps_ns);

 private:
  struct State;
  TrackerConfig config_;
  std::unique_ptr<State> state_;
};

}  // namespace tessera::fusion
