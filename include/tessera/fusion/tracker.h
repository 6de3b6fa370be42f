#pragma once
// Camera tracking: frame-to-frame RGB-D odometry (OpenCV's RgbdICPOdometry: photometric and
// point-to-plane ICP terms over a coarse-to-fine pyramid), with tracking-loss detection.
#include <memory>
#include <string>
#include <vector>

#include "tessera/core/config.h"
#include "tessera/core/frame.h"

namespace tessera::fusion {

struct TrackerConfig {
  double min_depth_m = 0.3;
  double max_depth_m = 4.0;
  double max_depth_difference_m = 0.07;  // correspondences farther apart in depth are dropped
  double max_translation_m = 0.15;       // per frame; a larger jump is a tracking loss
  double max_rotation_deg = 15.0;        // per frame; a larger turn is a tracking loss
  int lost_frames_before_restart = 10;   // then tracking restarts from the current frame
  // Gauss-Newton iterations per pyramid level, finest level first; the level count follows.
  std::vector<int> iterations_per_level = {3, 3, 4, 6};
};

void readConfig(const core::ConfigSection& section, TrackerConfig& config);

enum class TrackingStatus { kFirst, kTracked, kLost, kRestarted };

struct TrackingResult {
  TrackingStatus status = TrackingStatus::kFirst;
  core::Isometry T_W_C = core::Isometry::Identity();  // valid unless kLost
  std::string problem;                                // why tracking was lost
};

// Not thread-safe: owned by the fusion stage, which runs serially.
class Tracker {
 public:
  explicit Tracker(const TrackerConfig& config);
  ~Tracker();

  // The pose of `frame`. The first frame (and a restart) gets `initial_T_W_C`.
  TrackingResult track(const core::Frame& frame, const core::Isometry& initial_T_W_C);

 private:
  struct State;
  TrackerConfig config_;
  std::unique_ptr<State> state_;
};

}  // namespace tessera::fusion
