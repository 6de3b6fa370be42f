#include "tessera/fusion/tracker.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <deque>
#include <limits>
#include <memory>
#include <optional>

#include <fmt/format.h>
#include <opencv2/core/eigen.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/rgbd.hpp>

#include "tessera/core/error.h"
#include "tessera/core/registration.h"
#include "tessera/fusion/place_index.h"

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
  section.read("feature_gap_s", config.feature_gap_s);
  section.read("relocalisation_keyframes", config.relocalisation_keyframes);
  section.read("relocalise_against_all_keyframes", config.relocalise_against_all_keyframes);
  section.read("relocalisation_candidates", config.relocalisation_candidates);
  section.read("relocalisation_min_votes", config.relocalisation_min_votes);
  section.read("relocalisation_cover_radius_m", config.relocalisation_cover_radius_m);
  section.read("relocalisation_cover_angle_deg", config.relocalisation_cover_angle_deg);
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
  if (config.feature_gap_s <= 0.0 || config.relocalisation_keyframes < 1 ||
      config.relocalisation_candidates < 1 || config.relocalisation_min_votes < 1) {
    throw core::ConfigError(
        "tracker: feature_gap_s must be positive, relocalisation_keyframes, "
        "relocalisation_candidates and relocalisation_min_votes >= 1");
  }
  if (config.keyframe_translation_m < 0.0 || config.keyframe_rotation_deg < 0.0) {
    throw core::ConfigError(
        "tracker: keyframe_translation_m and keyframe_rotation_deg must be >= 0");
  }
}

namespace {

// A block of depth readings spread wider than this fraction of their mean straddles an edge.
constexpr double kBlockSpreadFraction = 0.03;

// A frame with fewer valid depth readings than this share of its pixels cannot be posed.
constexpr double kMinValidDepthFraction = 0.02;

// A solve is kept only if at least this share of the frame's points that land on the
// keyframe's depth agree with it within max_depth_difference_m. Measured on the office and TUM
// fr1_rpy: correct solves agree on 85-99%; wrong minima after a large motion on far fewer.
constexpr double kMinDepthAgreement = 0.6;

// The frame's grey (colour registered to depth) and depth in metres, NaN where missing.
void fullImages(const core::Frame& frame, cv::Mat& grey, cv::Mat& depth_m) {
  cv::cvtColor(core::registerColourToDepth(frame), grey, cv::COLOR_RGB2GRAY);
  frame.depth_mm.convertTo(depth_m, CV_32F, 1e-3);
  depth_m.setTo(std::numeric_limits<float>::quiet_NaN(), frame.depth_mm == 0);
}

// The odometry's inputs at 1/scale of the frame's resolution, each pixel the mean of a
// scale x scale block: grey by area, depth over the block's valid readings when they agree
// (else none, so that an edge is never blurred). Averaging rather than keeping one pixel per
// block matters on noisy depth: the solve's error grows with the noise of fewer points.
void blockImages(const cv::Mat& grey, const cv::Mat& depth_m, int scale, cv::Mat& grey_out,
                 cv::Mat& depth_out) {
  if (scale == 1) {
    grey_out = grey;
    depth_out = depth_m;
    return;
  }
  const cv::Size size(depth_m.cols / scale, depth_m.rows / scale);
  cv::resize(grey, grey_out, size, 0, 0, cv::INTER_AREA);
  depth_out.create(size, CV_32F);
  for (int v = 0; v < size.height; ++v) {
    auto* out = depth_out.ptr<float>(v);
    for (int u = 0; u < size.width; ++u) {
      int count = 0;
      double sum = 0.0;
      float low = std::numeric_limits<float>::max(), high = 0.0f;
      for (int dv = 0; dv < scale; ++dv) {
        const float* in = depth_m.ptr<float>(v * scale + dv) + u * scale;
        for (int du = 0; du < scale; ++du) {
          const float z = in[du];
          if (!std::isfinite(z)) continue;
          ++count;
          sum += z;
          low = std::min(low, z);
          high = std::max(high, z);
        }
      }
      const double mean = count > 0 ? sum / count : 0.0;
      out[u] = count > 0 && high - low <= kBlockSpreadFraction * mean
                   ? static_cast<float>(mean)
                   : std::numeric_limits<float>::quiet_NaN();
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
  out.linear() =
      Eigen::Quaterniond(Eigen::Matrix3d(T.topLeftCorner<3, 3>())).normalized().toRotationMatrix();
  out.translation() = T.topRightCorner<3, 1>();
  return out;
}

// The share of `depth_a`'s points (every 4th pixel) that, moved by T_b_a and projected into
// camera b, land on a depth of `depth_b` within `tolerance_m`; among those that land on any.
double depthAgreement(const cv::Mat& depth_a, const cv::Mat& depth_b, const cv::Matx33d& K,
                      const core::Isometry& T_b_a, double tolerance_m) {
  const double fx = K(0, 0), fy = K(1, 1), cx = K(0, 2), cy = K(1, 2);
  int landed = 0, agreed = 0;
  for (int v = 0; v < depth_a.rows; v += 4) {
    const float* row = depth_a.ptr<float>(v);
    for (int u = 0; u < depth_a.cols; u += 4) {
      const double z = row[u];
      if (!std::isfinite(z)) continue;
      const Eigen::Vector3d p_b = T_b_a * Eigen::Vector3d((u - cx) * z / fx, (v - cy) * z / fy, z);
      if (p_b.z() <= 0.0) continue;
      const long ub = std::lround(fx * p_b.x() / p_b.z() + cx);
      const long vb = std::lround(fy * p_b.y() / p_b.z() + cy);
      if (ub < 0 || vb < 0 || ub >= depth_b.cols || vb >= depth_b.rows) continue;
      const float zb = depth_b.at<float>(static_cast<int>(vb), static_cast<int>(ub));
      if (!std::isfinite(zb)) continue;
      ++landed;
      if (std::abs(zb - p_b.z()) <= tolerance_m) ++agreed;
    }
  }
  return landed > 0 ? static_cast<double>(agreed) / landed : 0.0;
}

// A frame as the tracker keeps it: its odometry cache, the block-averaged depth the cache was
// built from (for the agreement check) and the full-resolution images (for features).
struct TrackedImages {
  cv::Ptr<cv::rgbd::OdometryFrame> odometry;
  cv::Mat depth_small;
  cv::Mat grey, depth_m;
};

struct Keyframe {
  int id = 0;            // in the order made
  std::int64_t timestamp_ns = 0;
  TrackedImages images;  // odometry cache built for the destination role
  core::Isometry T_W_C = core::Isometry::Identity();
  SharedFeatures features;
};

// A keyframe as kept for relocalisation once its images are dropped.
struct PastKeyframe {
  int id = -1;  // the keyframe's; its place in the index is its place in State::past
  std::int64_t timestamp_ns = 0;
  core::Isometry T_W_C = core::Isometry::Identity();
  SharedFeatures features;
};

// The place of the newest kept keyframe older than keyframe `id` in `past` (ascending ids),
// or -1 when there is none.
int newestKeptBefore(const std::vector<PastKeyframe>& past, int id) {
  const auto older = std::partition_point(past.begin(), past.end(),
                                          [id](const PastKeyframe& p) { return p.id < id; });
  return static_cast<int>(older - past.begin()) - 1;
}

// The query descriptors of a relocalisation lookup (the strongest corners; as loop closure's).
constexpr int kRelocalisationQueryDescriptors = 300;

}  // namespace

struct Tracker::State {
  cv::Ptr<cv::rgbd::RgbdICPOdometry> odometry;
  cv::Matx33d camera_matrix;  // at the tracking scale
  // Each frame is the odometry's source and a keyframe its destination. A source needs only
  // pyramids and points (3 ms at 640x480); the destination's normals and gradients (18 ms) are
  // built once per keyframe, and errors add up keyframe by keyframe, not frame by frame. The
  // newest keyframe (back) is tracked against; the others are kept to relocalise against.
  std::deque<std::shared_ptr<Keyframe>> keyframes;
  std::shared_ptr<Keyframe> reference;  // the keyframe frames are tracked against
  // Every keyframe so far but revisits of a place already kept (ascending ids), and their
  // descriptors in a place index: what a frame that none of the recent keyframes recognises
  // is looked up in.
  std::vector<PastKeyframe> past;
  PlaceIndex places;
  int keyframes_made = 0;
  // The last tracked frame: its images, pose and time.
  TrackedImages previous;
  core::Isometry T_W_previous = core::Isometry::Identity();
  std::int64_t previous_timestamp_ns = 0;
  // The last frame-to-frame motion (T_current_previous) and the time it took, for the
  // constant-velocity guess; unset after a loss or restart.
  std::optional<core::Isometry> last_motion;
  std::int64_t last_motion_ns = 0;
  int lost_in_a_row = 0;
  bool interrupted = false;
  int segment_first_id = 0;  // the first keyframe of the segment tracked now
  // An earlier session's map was given (continueMap) and no frame is posed in it yet.
  bool awaiting_map = false;
  // past[i] for i below this is a continued map's keyframe in another frame than this
  // session's (the session was not found in it): never a relocalisation candidate.
  std::size_t first_in_frame = 0;
  // This session's keyframes start at past[continued]; earlier ones are a continued map's.
  std::size_t continued = 0;
  bool cover_by_loop_closure = false;  // leaveCoverToLoopClosure()
};

Tracker::Tracker(const TrackerConfig& config)
    : config_(config), state_(std::make_unique<State>()) {}

Tracker::~Tracker() = default;

void Tracker::sourceInterrupted() {
  state_->interrupted = true;
  state_->last_motion.reset();
}

void Tracker::continueMap(const std::vector<MapKeyframe>& keyframes) {
  State& s = *state_;
  if (s.reference) throw core::Error("Tracker::continueMap: call it before the first frame");
  for (const MapKeyframe& keyframe : keyframes) {
    s.places.add(static_cast<int>(s.past.size()), keyframe.features->descriptors);
    s.past.push_back(
        {s.keyframes_made++, keyframe.timestamp_ns, keyframe.T_W_C, keyframe.features});
  }
  s.awaiting_map = !s.past.empty();
  s.continued = s.past.size();
}

void Tracker::leaveCoverToLoopClosure() {
  if (state_->reference) {
    throw core::Error("Tracker::leaveCoverToLoopClosure: call it before the first frame");
  }
  state_->cover_by_loop_closure = true;
}

std::size_t Tracker::forgetKeyframes(const std::vector<std::int64_t>& timestamps_ns) {
  State& s = *state_;
  std::size_t forgotten = 0;
  // This session's keyframes ascend in time.
  const auto first = s.past.begin() + static_cast<std::ptrdiff_t>(s.continued);
  for (const std::int64_t t : timestamps_ns) {
    const auto it = std::partition_point(first, s.past.end(),
                                         [t](const PastKeyframe& p) { return p.timestamp_ns < t; });
    if (it == s.past.end() || it->timestamp_ns != t || it->features == nullptr) continue;
    s.places.remove(static_cast<int>(it - s.past.begin()));
    it->features.reset();
    ++forgotten;
  }
  return forgotten;
}

TrackingResult Tracker::track(const core::Frame& frame, const core::Isometry& initial_T_W_C) {
  const core::Intrinsics& k = frame.intrinsics;
  State& s = *state_;
  if (!s.odometry) {
    // A block's mean sits at the centre of its pixels: u_block = (u - (scale - 1) / 2) / scale.
    const double scale = config_.tracking_scale;
    const double shift = (scale - 1.0) / 2.0;
    s.camera_matrix = cv::Matx33d(k.fx / scale, 0, (k.cx - shift) / scale, 0, k.fy / scale,
                                  (k.cy - shift) / scale, 0, 0, 1);
    s.odometry = cv::rgbd::RgbdICPOdometry::create(
        cv::Mat(s.camera_matrix), static_cast<float>(config_.min_depth_m),
        static_cast<float>(config_.max_depth_m),
        static_cast<float>(config_.max_depth_difference_m));
    s.odometry->setIterationCounts(cv::Mat(config_.iterations_per_level, true));
    // One gradient threshold per level (OpenCV's default value).
    s.odometry->setMinGradientMagnitudes(
        cv::Mat(std::vector<float>(config_.iterations_per_level.size(), 10.0f), true));
  }
  TrackedImages current;
  fullImages(frame, current.grey, current.depth_m);
  cv::Mat grey_small;
  blockImages(current.grey, current.depth_m, config_.tracking_scale, grey_small,
              current.depth_small);
  current.odometry = cv::rgbd::OdometryFrame::create(grey_small, current.depth_small);

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
  // Whether a keyframe at T_W_C revisits the place of one kept before the recent ones.
  const auto coveredByPast = [&](const core::Isometry& T_W_C) {
    if (s.cover_by_loop_closure || config_.relocalisation_cover_radius_m <= 0.0 ||
        s.keyframes.empty()) {
      return false;
    }
    const int recent = s.keyframes.front()->id;
    for (auto past = s.past.begin() + static_cast<std::ptrdiff_t>(s.first_in_frame);
         past != s.past.end(); ++past) {
      if (past->id >= recent) break;
      if (core::posesNear(past->T_W_C, T_W_C, config_.relocalisation_cover_radius_m,
                          config_.relocalisation_cover_angle_deg)) {
        return true;
      }
    }
    return false;
  };
  // Makes `images` (posed at T_W_C) the keyframe frames are tracked against.
  const auto makeKeyframe = [&](const TrackedImages& images, const core::Isometry& T_W_C,
                                std::int64_t timestamp_ns, bool starts_segment,
                                std::optional<std::int64_t> relocalised_against_ns = {},
                                bool found_in_continued_map = false) {
    if (!prepare(images.odometry, cv::rgbd::OdometryFrame::CACHE_DST)) return false;
    auto keyframe = std::make_shared<Keyframe>();
    keyframe->id = s.keyframes_made++;
    keyframe->timestamp_ns = timestamp_ns;
    if (starts_segment) s.segment_first_id = keyframe->id;
    keyframe->images = images;
    keyframe->T_W_C = T_W_C;
    keyframe->features = std::make_shared<const FeatureFrame>(
        describeFeatures(images.grey, images.depth_m, k, config_.features));
    const bool relocalisation = config_.relocalise_against_all_keyframes && !coveredByPast(T_W_C);
    if (relocalisation) {
      s.places.add(static_cast<int>(s.past.size()), keyframe->features->descriptors);
      s.past.push_back({keyframe->id, timestamp_ns, T_W_C, keyframe->features});
    }
    auto record = std::make_shared<KeyframeRecord>();
    record->timestamp_ns = timestamp_ns;
    record->T_W_C = T_W_C;
    record->features = keyframe->features;
    record->depth_m = images.depth_m;
    record->intrinsics = k;
    record->starts_segment = starts_segment;
    record->relocalised_against_ns = relocalised_against_ns;
    record->found_in_continued_map = found_in_continued_map;
    record->relocalisation = relocalisation;
    result.new_keyframes.push_back(std::move(record));
    s.keyframes.push_back(keyframe);
    while (static_cast<int>(s.keyframes.size()) > std::max(1, config_.relocalisation_keyframes)) {
      s.keyframes.pop_front();
    }
    s.reference = keyframe;
    return true;
  };
  const auto accept = [&](TrackingStatus status, const core::Isometry& T_W_C, std::int64_t gap_ns) {
    if (gap_ns > 0 && status == TrackingStatus::kTracked) {
      s.last_motion = T_W_C.inverse() * s.T_W_previous;
      s.last_motion_ns = gap_ns;
    } else {
      s.last_motion.reset();  // no timestamps, or a new start: no velocity to go by
    }
    s.previous = current;
    s.T_W_previous = T_W_C;
    s.previous_timestamp_ns = frame.timestamp_ns;
    s.lost_in_a_row = 0;
    s.interrupted = false;
    result.status = status;
    result.T_W_C = T_W_C;
    return result;
  };
  const int valid_depth = cv::countNonZero(current.depth_small == current.depth_small);  // not NaN
  if (valid_depth < kMinValidDepthFraction * static_cast<double>(current.depth_small.total())) {
    result.problem = fmt::format("frame has almost no valid depth ({} of {} pixels)", valid_depth,
                                 current.depth_small.total());
    ++s.lost_in_a_row;
    result.status = TrackingStatus::kLost;
    return result;
  }
  const bool prepared = prepare(current.odometry, cv::rgbd::OdometryFrame::CACHE_SRC);
  std::optional<FeatureFrame> current_features;
  // The pose of the current frame from features against the most voted of the kept
  // keyframes up to `newest_allowed` (-1: all) that gives one, and that keyframe.
  const auto lookUpPlaces =
      [&](int newest_allowed) -> std::optional<std::pair<core::Isometry, const PastKeyframe*>> {
    PlaceQuery query;
    query.min_votes = config_.relocalisation_min_votes;
    query.max_candidates = config_.relocalisation_candidates;
    query.newest_allowed = newest_allowed;
    if (!current_features) {
      current_features = describeFeatures(current.grey, current.depth_m, k, config_.features);
    }
    const std::vector<PlaceCandidate> candidates = s.places.query(
        strongestDescriptors(*current_features, kRelocalisationQueryDescriptors), query);
    for (const PlaceCandidate& candidate : candidates) {
      if (static_cast<std::size_t>(candidate.keyframe) < s.first_in_frame) continue;
      const PastKeyframe& key = s.past[static_cast<std::size_t>(candidate.keyframe)];
      const auto pose = estimateFeaturePose(*key.features, *current_features, k, config_.features);
      if (pose) {
        return std::pair{core::Isometry(key.T_W_C * pose->T_current_reference.inverse()), &key};
      }
    }
    return std::nullopt;
  };
  if (prepared && !s.reference && s.awaiting_map) {
    // A continued map: the session starts where its first frame is found in it.
    if (const auto found = lookUpPlaces(-1)) {
      if (!makeKeyframe(current, found->first, frame.timestamp_ns, true)) {
        result.status = TrackingStatus::kLost;
        return result;
      }
      s.awaiting_map = false;
      result.from_features = true;
      result.relocalised_globally = true;
      return accept(TrackingStatus::kRelocalised, found->first, 0);
    }
    if (++s.lost_in_a_row < config_.lost_frames_before_restart) {
      result.problem = "not found in the continued map yet";
      result.status = TrackingStatus::kLost;
      return result;
    }
    s.awaiting_map = false;
    s.first_in_frame = s.past.size();
    result.problem = fmt::format(
        "not found in the continued map in {} frames: this session maps in its own frame",
        s.lost_in_a_row);
  }
  if (prepared && !s.reference) {
    if (!makeKeyframe(current, initial_T_W_C, frame.timestamp_ns, true)) {
      result.status = TrackingStatus::kLost;
      return result;
    }
    return accept(TrackingStatus::kFirst, initial_T_W_C, 0);
  }

  // The time since the last tracked frame over the time the last motion took: more than one
  // when frames were dropped or lost. The guess stretches with it, and so do the motion bounds.
  const std::int64_t gap_ns = frame.timestamp_ns - s.previous_timestamp_ns;
  const double ratio =
      s.last_motion && s.last_motion_ns > 0 && gap_ns > 0
          ? std::min(static_cast<double>(gap_ns) / static_cast<double>(s.last_motion_ns),
                     static_cast<double>(config_.lost_frames_before_restart + 1))
          : 1.0;
  const double bound_scale = std::max(1.0, ratio);
  core::Isometry T_W_guess =
      config_.constant_velocity && s.last_motion
          ? core::Isometry(s.T_W_previous * stretched(*s.last_motion, ratio).inverse())
          : s.T_W_previous;

  // Dense odometry against keyframe `key` from T_W_guess; the pose, if it converged within
  // the bounds and the depths agree.
  const auto solve = [&](const Keyframe& key) -> std::optional<core::Isometry> {
    cv::Mat guess, Rt;  // key_p = Rt * current_p; OpenCV wants 4x4 CV_64FC1 matrices
    cv::eigen2cv(Eigen::Matrix4d((key.T_W_C.inverse() * T_W_guess).matrix()), guess);
    try {
      s.odometry->setMaxTranslation(config_.max_translation_m * bound_scale);
      s.odometry->setMaxRotation(config_.max_rotation_deg * bound_scale);
      cv::Ptr<cv::rgbd::OdometryFrame> destination = key.images.odometry;
      if (!s.odometry->compute(current.odometry, destination, Rt, guess)) {
        return std::nullopt;
      }
    } catch (const cv::Exception& e) {
      result.problem = fmt::format("odometry failed: {}", e.what());
      return std::nullopt;
    }
    Eigen::Matrix4d T;
    cv::cv2eigen(Rt, T);
    const core::Isometry T_key_current = rigid(T);
    if (depthAgreement(current.depth_small, key.images.depth_small, s.camera_matrix, T_key_current,
                       config_.max_depth_difference_m) < kMinDepthAgreement) {
      result.problem = "odometry converged to a pose the depths disagree with";
      return std::nullopt;
    }
    return key.T_W_C * T_key_current;
  };
  // The pose of the current frame from features against keyframe `key`, as the new guess.
  const auto guessFromFeatures = [&](const Keyframe& key) {
    if (!current_features) {
      current_features = describeFeatures(current.grey, current.depth_m, k, config_.features);
    }
    const auto pose = estimateFeaturePose(*key.features, *current_features, k, config_.features);
    if (pose) {
      T_W_guess = key.T_W_C * pose->T_current_reference.inverse();
      result.from_features = true;
    }
    return pose.has_value();
  };

  std::optional<core::Isometry> T_W_C;
  TrackingStatus status = TrackingStatus::kTracked;
  if (prepared && (s.interrupted || s.lost_in_a_row > 0)) {
    // Relocalise: the newest keyframe whose features give a pose, refined densely against it.
    for (auto it = s.keyframes.rbegin(); it != s.keyframes.rend() && !T_W_C; ++it) {
      if (!guessFromFeatures(**it)) continue;
      T_W_C = solve(**it);
      if (!T_W_C) T_W_C = T_W_guess;  // the feature pose alone: still better than none
      s.reference = *it;
      status = TrackingStatus::kRelocalised;
    }
    if (T_W_C && s.reference->id < s.segment_first_id) {
      // Found against a keyframe made before the last restart: the pose is in that keyframe's
      // segment, not in the one tracking restarted. The frame starts a segment there, which loop
      // closure joins to that keyframe's once it verifies the pair.
      if (makeKeyframe(current, *T_W_C, frame.timestamp_ns, true, s.reference->timestamp_ns)) {
        return accept(TrackingStatus::kRelocalised, *T_W_C, 0);
      }
    }
    if (!T_W_C && config_.relocalise_against_all_keyframes && !s.keyframes.empty()) {
      // Older keyframes: the most voted first; the feature pose alone (their images are gone),
      // and the frame becomes a keyframe that starts a segment there. The recent keyframes
      // were tried: only those kept before them are candidates.
      const int newest_allowed = newestKeptBefore(s.past, s.keyframes.front()->id);
      if (const auto found = newest_allowed < 0 ? std::nullopt : lookUpPlaces(newest_allowed)) {
        // A continued map's keyframe is not in this session's loop closure: its frame is the
        // map's already (the session was found in it, or it would not be a candidate).
        const bool continued_map =
            static_cast<std::size_t>(found->second - s.past.data()) < s.continued;
        if (makeKeyframe(current, found->first, frame.timestamp_ns, true,
                         continued_map ? std::nullopt
                                       : std::optional<std::int64_t>(found->second->timestamp_ns),
                         continued_map)) {
          result.from_features = true;
          result.relocalised_globally = true;
          return accept(TrackingStatus::kRelocalised, found->first, 0);
        }
      }
    }
    if (!T_W_C && s.interrupted) {
      result.problem = "not relocalised after the source was interrupted";
    }
  }
  if (prepared && !T_W_C && !s.interrupted) {
    // A large gap in time: features first. Otherwise dense from the motion guess, then
    // features when that fails (a keyframe recording's steps do not show in its clock).
    const bool large_gap = gap_ns > static_cast<std::int64_t>(config_.feature_gap_s * 1e9);
    if (large_gap) guessFromFeatures(*s.reference);
    T_W_C = solve(*s.reference);
    if (!T_W_C && s.previous.odometry != s.reference->images.odometry &&
        makeKeyframe(s.previous, s.T_W_previous, s.previous_timestamp_ns, false)) {
      // The keyframe may be too far from this view: try again from the last tracked frame.
      T_W_C = solve(*s.reference);
    }
    if (!T_W_C && !result.from_features && guessFromFeatures(*s.reference)) {
      T_W_C = solve(*s.reference);
      if (!T_W_C) T_W_C = T_W_guess;
    }
  }
  if (!T_W_C) {
    if (result.problem.empty()) {
      result.problem =
          "odometry found no motion within the bounds (too few correspondences, "
          "or a jump above the translation or rotation limit)";
    }
    if (++s.lost_in_a_row >= config_.lost_frames_before_restart && prepared) {
      // Not found again: a new segment starts at the last good pose. The old keyframes stay,
      // so that a later frame that sees them again brings the map back together.
      if (makeKeyframe(current, s.T_W_previous, frame.timestamp_ns, true)) {
        return accept(TrackingStatus::kRestarted, s.T_W_previous, 0);
      }
    }
    result.status = TrackingStatus::kLost;
    return result;
  }
  const core::Isometry T_key_current = s.reference->T_W_C.inverse() * *T_W_C;
  accept(status, *T_W_C, gap_ns);
  if (T_key_current.translation().norm() > config_.keyframe_translation_m ||
      core::rotationAngleDeg(T_key_current) > config_.keyframe_rotation_deg) {
    makeKeyframe(current, *T_W_C, frame.timestamp_ns, false);
  }
  return result;
}

}  // namespace tessera::fusion
