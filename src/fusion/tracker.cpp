#include "tessera/fusion/tracker.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <optional>

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
  section.read("tracking_scale", config.tracking_scale);
  section.read("keyframe_translation_m", config.keyframe_translation_m);
  section.read("keyframe_rotation_deg", config.keyframe_rotation_deg);
  section.read("constant_velocity", config.constant_velocity);
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
  if (config.tracking_scale != 1 && config.tracking_scale != 2 && config.tracking_scale != 4) {
    throw core::ConfigError("tracker: tracking_scale must be 1, 2 or 4");
  }
  if (config.keyframe_translation_m < 0.0 || config.keyframe_rotation_deg < 0.0) {
    throw core::ConfigError("tracker: keyframe_translation_m and keyframe_rotation_deg must be >= 0");
  }
}

namespace {

// A block of depth readings spread wider than this fraction of their mean straddles an edge.
constexpr double kBlockSpreadFraction = 0.03;

// The odometry's inputs at 1/scale of the frame's resolution, each pixel the mean of a
// scale x scale block: grey by area, depth over the block's valid readings when they agree
// (else none, so that an edge is never blurred). Averaging rather than sampling one pixel per
// block matters on noisy depth: on the synthetic Kinect office, sampling drifted 1.5x more.
void odometryImages(const core::Frame& frame, int scale, cv::Mat& grey, cv::Mat& depth_m) {
  cv::cvtColor(core::registerColourToDepth(frame), grey, cv::COLOR_RGB2GRAY);
  const float no_depth = std::numeric_limits<float>::quiet_NaN();
  if (scale == 1) {
    frame.depth_mm.convertTo(depth_m, CV_32F, 1e-3);
    depth_m.setTo(no_depth, frame.depth_mm == 0);
    return;
  }
  const cv::Size size(frame.depth_mm.cols / scale, frame.depth_mm.rows / scale);
  cv::resize(grey, grey, size, 0, 0, cv::INTER_AREA);
  depth_m.create(size, CV_32F);
  for (int v = 0; v < size.height; ++v) {
    auto* out = depth_m.ptr<float>(v);
    for (int u = 0; u < size.width; ++u) {
      int count = 0, sum = 0, low = std::numeric_limits<int>::max(), high = 0;
      for (int dv = 0; dv < scale; ++dv) {
        const auto* in = frame.depth_mm.ptr<std::uint16_t>(v * scale + dv) + u * scale;
        for (int du = 0; du < scale; ++du) {
          const int mm = in[du];
          if (mm == 0) continue;
          ++count;
          sum += mm;
          low = std::min(low, mm);
          high = std::max(high, mm);
        }
      }
      const double mean_mm = count > 0 ? static_cast<double>(sum) / count : 0.0;
      out[u] = count > 0 && high - low <= kBlockSpreadFraction * mean_mm
                   ? static_cast<float>(mean_mm * 1e-3)
                   : no_depth;
    }
  }
}

// The rigid motion `T` stretched by `ratio` (its rotation angle and translation scaled alike):
// the motion over `ratio` frame intervals at the velocity `T` took over one.
core::Isometry stretched(const core::Isometry& T, double ratio) {
  const Eigen::AngleAxisd turn(T.linear());
  core::Isometry out = core::Isometry::Identity();
  out.linear() = Eigen::AngleAxisd(turn.angle() * ratio, turn.axis()).toRotationMatrix();
  out.translation() = T.translation() * ratio;
  return out;
}

// The nearest rigid motion to OpenCV's 4x4 result, whose rotation part is a product of solver
// steps and is not quite orthonormal. Composed into the next guess unrepaired, the error grows
// frame by frame (a 2% scale within 30 frames of the synthetic office) and tracking is lost.
core::Isometry rigid(const Eigen::Matrix4d& T) {
  core::Isometry out = core::Isometry::Identity();
  out.linear() = Eigen::Quaterniond(Eigen::Matrix3d(T.topLeftCorner<3, 3>())).normalized()
                     .toRotationMatrix();
  out.translation() = T.topRightCorner<3, 1>();
  return out;
}

double angleDeg(const core::Isometry& T) {
  return Eigen::AngleAxisd(T.linear()).angle() * 180.0 / M_PI;
}

}  // namespace

struct Tracker::State {
  cv::Ptr<cv::rgbd::RgbdICPOdometry> odometry;
  // Each frame is the odometry's source and the keyframe its destination. A source needs only
  // pyramids and points (3 ms at 640x480); the destination's normals and gradients (18 ms) are
  // built once per keyframe. Errors add up keyframe by keyframe, not frame by frame.
  cv::Ptr<cv::rgbd::OdometryFrame> keyframe;
  core::Isometry T_W_keyframe = core::Isometry::Identity();
  // The last tracked frame: its pose, time and source cache.
  cv::Ptr<cv::rgbd::OdometryFrame> previous;
  core::Isometry T_W_previous = core::Isometry::Identity();
  std::int64_t previous_timestamp_ns = 0;
  // The last frame-to-frame motion (T_current_previous) and the time it took, for the
  // constant-velocity guess; unset after a loss or restart.
  std::optional<core::Isometry> last_motion;
  std::int64_t last_motion_ns = 0;
  int lost_in_a_row = 0;
};

Tracker::Tracker(const TrackerConfig& config)
    : config_(config), state_(std::make_unique<State>()) {}

Tracker::~Tracker() = default;

TrackingResult Tracker::track(const core::Frame& frame, const core::Isometry& initial_T_W_C) {
  const core::Intrinsics& k = frame.intrinsics;
  State& s = *state_;
  if (!s.odometry) {
    // A block's mean sits at the centre of its pixels: u_block = (u - (scale - 1) / 2) / scale.
    const double scale = config_.tracking_scale;
    const double shift = (scale - 1.0) / 2.0;
    const cv::Mat camera_matrix =
        (cv::Mat_<double>(3, 3) << k.fx / scale, 0, (k.cx - shift) / scale, 0, k.fy / scale,
         (k.cy - shift) / scale, 0, 0, 1);
    s.odometry =
        cv::rgbd::RgbdICPOdometry::create(camera_matrix, static_cast<float>(config_.min_depth_m),
                                          static_cast<float>(config_.max_depth_m),
                                          static_cast<float>(config_.max_depth_difference_m));
    s.odometry->setIterationCounts(cv::Mat(config_.iterations_per_level, true));
    // One gradient threshold per level (OpenCV's default value).
    s.odometry->setMinGradientMagnitudes(
        cv::Mat(std::vector<float>(config_.iterations_per_level.size(), 10.0f), true));
  }
  cv::Mat grey, depth;
  odometryImages(frame, config_.tracking_scale, grey, depth);
  cv::Ptr<cv::rgbd::OdometryFrame> current = cv::rgbd::OdometryFrame::create(grey, depth);

  TrackingResult result;
  const auto prepare = [&](cv::Ptr<cv::rgbd::OdometryFrame> odometry_frame, int cache) {
    try {
      s.odometry->prepareFrameCache(odometry_frame, cache);
      return true;
    } catch (const cv::Exception& e) {
      result.problem = fmt::format("frame unusable for odometry: {}", e.what());
      return false;
    }
  };
  const bool prepared = prepare(current, cv::rgbd::OdometryFrame::CACHE_SRC);
  const auto restart = [&](TrackingStatus status, const core::Isometry& T_W_C) {
    if (!prepare(current, cv::rgbd::OdometryFrame::CACHE_DST)) {
      result.status = TrackingStatus::kLost;
      return result;
    }
    s.keyframe = s.previous = current;
    s.T_W_keyframe = s.T_W_previous = T_W_C;
    s.previous_timestamp_ns = frame.timestamp_ns;
    s.last_motion.reset();
    s.lost_in_a_row = 0;
    result.status = status;
    result.T_W_C = T_W_C;
    return result;
  };
  if (!s.keyframe && prepared) return restart(TrackingStatus::kFirst, initial_T_W_C);

  // The time since the last tracked frame over the time the last motion took: more than one
  // when frames were dropped or lost. The guess stretches with it, and so do the motion bounds.
  const std::int64_t gap_ns = frame.timestamp_ns - s.previous_timestamp_ns;
  const double ratio =
      s.last_motion && s.last_motion_ns > 0 && gap_ns > 0
          ? std::min(static_cast<double>(gap_ns) / static_cast<double>(s.last_motion_ns),
                     static_cast<double>(config_.lost_frames_before_restart + 1))
          : 1.0;
  const double bound_scale = std::max(1.0, ratio);
  const core::Isometry T_W_guess =
      config_.constant_velocity && s.last_motion
          ? core::Isometry(s.T_W_previous * stretched(*s.last_motion, ratio).inverse())
          : s.T_W_previous;
  const auto solve = [&](core::Isometry& T_keyframe_current) {
    cv::Mat guess, Rt;  // keyframe_p = Rt * current_p; OpenCV wants 4x4 CV_64FC1 matrices
    cv::eigen2cv(Eigen::Matrix4d((s.T_W_keyframe.inverse() * T_W_guess).matrix()), guess);
    try {
      s.odometry->setMaxTranslation(config_.max_translation_m * bound_scale);
      s.odometry->setMaxRotation(config_.max_rotation_deg * bound_scale);

      if (!s.odometry->compute(current, s.keyframe, Rt, guess)) return false;
    } catch (const cv::Exception& e) {
      result.problem = fmt::format("odometry failed: {}", e.what());
      return false;
    }
    Eigen::Matrix4d T;
    cv::cv2eigen(Rt, T);
    T_keyframe_current = rigid(T);
    return true;
  };
  core::Isometry T_keyframe_current;
  bool ok = prepared && solve(T_keyframe_current);
  if (!ok && prepared && s.previous != s.keyframe &&
      prepare(s.previous, cv::rgbd::OdometryFrame::CACHE_DST)) {
    // The keyframe may be too far from this view: try again from the last tracked frame.
    s.keyframe = s.previous;
    s.T_W_keyframe = s.T_W_previous;
    ok = solve(T_keyframe_current);
  }
  if (!ok) {
    if (result.problem.empty()) {
      result.problem =
          "odometry found no motion within the bounds (too few correspondences, "
          "or a jump above the translation or rotation limit)";
    }
    if (++s.lost_in_a_row >= config_.lost_frames_before_restart && prepared) {
      // Start a new segment at the last good pose: the map stays consistent around it.
      return restart(TrackingStatus::kRestarted, s.T_W_previous);
    }
    result.status = TrackingStatus::kLost;
    return result;
  }
  const core::Isometry T_W_C = s.T_W_keyframe * T_keyframe_current;
  if (gap_ns > 0) {
    s.last_motion = T_W_C.inverse() * s.T_W_previous;
    s.last_motion_ns = gap_ns;
  } else {
    s.last_motion.reset();  // no timestamps: no velocity to go by
  }
  s.previous = current;
  s.previous_timestamp_ns = frame.timestamp_ns;
  s.T_W_previous = T_W_C;
  s.lost_in_a_row = 0;
  if (T_keyframe_current.translation().norm() > config_.keyframe_translation_m ||
      angleDeg(T_keyframe_current) > config_.keyframe_rotation_deg) {
    if (prepare(current, cv::rgbd::OdometryFrame::CACHE_DST)) {
      s.keyframe = current;
      s.T_W_keyframe = T_W_C;
    }
  }
  result.status = TrackingStatus::kTracked;
  result.T_W_C = T_W_C;
  return result;
}

}  // namespace tessera::fusion
