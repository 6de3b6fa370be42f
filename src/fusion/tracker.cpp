#include "tessera/fusion/tracker.h"

#include <algorithm>
#include <cmath>

#include <fmt/format.h>
#include <opencv2/core/eigen.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/rgbd.hpp>

#include "tessera/core/error.h"
#include "tessera/core/registration.h"

namespace tessera::fusion {

void readConfig(const core::ConfigSection& section, TrackerConfig& config) {
  section.read("min_depth_m", config.min_depth_m);
  section.read("max_depth_m", config.max_depth_m);
  section.read("max_depth_difference_m", config.max_depth_difference_m);
  section.read("max_translation_m", config.max_translation_m);
  section.read("max_rotation_deg", config.max_rotation_deg);
  section.read("lost_frames_before_restart", config.lost_frames_before_restart);
  section.read("iterations_per_level", config.iterations_per_level);
  if (config.max_depth_m <= config.min_depth_m || config.max_translation_m <= 0.0 ||
      config.max_rotation_deg <= 0.0 || config.lost_frames_before_restart < 1) {
    throw core::ConfigError(
        "tracker: need min_depth_m < max_depth_m, positive jump bounds and "
        "lost_frames_before_restart >= 1");
  }
  const auto& levels = config.iterations_per_level;
  if (levels.empty() || levels.size() > 6 ||
      std::any_of(levels.begin(), levels.end(), [](int n) { return n < 1; })) {
    throw core::ConfigError(
        "tracker: iterations_per_level needs 1 to 6 levels of at least one iteration each");
  }
}

struct Tracker::State {
  cv::Ptr<cv::rgbd::RgbdICPOdometry> odometry;
  cv::Mat camera_matrix;
  // The last well-tracked frame with its pyramids, normals and gradients already built, so
  // each frame's cache is computed once although it serves as destination, then as source.
  cv::Ptr<cv::rgbd::OdometryFrame> previous;
  core::Isometry T_W_previous = core::Isometry::Identity();
  int lost_in_a_row = 0;
};

Tracker::Tracker(const TrackerConfig& config)
    : config_(config), state_(std::make_unique<State>()) {}

Tracker::~Tracker() = default;

TrackingResult Tracker::track(const core::Frame& frame, const core::Isometry& initial_T_W_C) {
  const core::Intrinsics& k = frame.intrinsics;
  State& s = *state_;
  if (!s.odometry) {
    s.camera_matrix = (cv::Mat_<double>(3, 3) << k.fx, 0, k.cx, 0, k.fy, k.cy, 0, 0, 1);
    s.odometry =
        cv::rgbd::RgbdICPOdometry::create(s.camera_matrix, static_cast<float>(config_.min_depth_m),
                                          static_cast<float>(config_.max_depth_m),
                                          static_cast<float>(config_.max_depth_difference_m));
    s.odometry->setMaxTranslation(config_.max_translation_m);
    s.odometry->setMaxRotation(config_.max_rotation_deg);
    s.odometry->setIterationCounts(cv::Mat(config_.iterations_per_level, true));
    // One gradient threshold per level (OpenCV's default value).
    s.odometry->setMinGradientMagnitudes(
        cv::Mat(std::vector<float>(config_.iterations_per_level.size(), 10.0f), true));
  }
  cv::Mat grey, depth;
  cv::cvtColor(core::registerColourToDepth(frame), grey, cv::COLOR_RGB2GRAY);
  frame.depth_mm.convertTo(depth, CV_32F, 1e-3);
  depth.setTo(std::numeric_limits<float>::quiet_NaN(), frame.depth_mm == 0);
  cv::Ptr<cv::rgbd::OdometryFrame> current = cv::rgbd::OdometryFrame::create(grey, depth);

  TrackingResult result;
  bool prepared = false;
  try {
    // Prepared for both roles: as destination now, as source for the next frame.
    s.odometry->prepareFrameCache(current, cv::rgbd::OdometryFrame::CACHE_ALL);
    prepared = true;
  } catch (const cv::Exception& e) {
    result.problem = fmt::format("frame unusable for odometry: {}", e.what());
  }
  const auto restart = [&](TrackingStatus status) {
    s.previous = current;
    s.T_W_previous = initial_T_W_C;
    s.lost_in_a_row = 0;
    result.status = status;
    result.T_W_C = initial_T_W_C;
    return result;
  };
  if (!s.previous && prepared) return restart(TrackingStatus::kFirst);

  cv::Mat Rt;  // current_p = Rt * previous_p
  bool ok = false;
  if (prepared && s.previous) {
    try {
      ok = s.odometry->compute(s.previous, current, Rt);
    } catch (const cv::Exception& e) {
      result.problem = fmt::format("odometry failed: {}", e.what());
    }
  }
  if (!ok) {
    if (result.problem.empty()) {
      result.problem =
          "odometry found no motion within the bounds (too few correspondences, "
          "or a jump above the translation or rotation limit)";
    }
    if (++s.lost_in_a_row >= config_.lost_frames_before_restart && prepared && s.previous) {
      // Start a new segment at the last good pose: the map stays consistent around it.
      const core::Isometry last_good = s.T_W_previous;
      TrackingResult restarted = restart(TrackingStatus::kRestarted);
      restarted.T_W_C = s.T_W_previous = last_good;
      return restarted;
    }
    result.status = TrackingStatus::kLost;
    return result;
  }
  Eigen::Matrix4d T_current_previous;
  cv::cv2eigen(Rt, T_current_previous);
  const core::Isometry T_W_C = s.T_W_previous * core::Isometry(T_current_previous).inverse();
  s.previous = current;
  s.T_W_previous = T_W_C;
  s.lost_in_a_row = 0;
  result.status = TrackingStatus::kTracked;
  result.T_W_C = T_W_C;
  return result;
}

}  // namespace tessera::fusion
