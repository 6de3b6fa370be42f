// The frame path's stages: source, tracking, integration and planes.
#include "tessera/pipeline/stages.h"

#include <algorithm>
#include <chrono>

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include "tessera/core/clock.h"
#include "tessera/core/error.h"
#include "tessera/core/registration.h"

namespace tessera::pipeline {

namespace {

// A frame this far from a reference one (5 cm or 3 degrees: a recording of sparse keyframes,
// dropped frames) is always integrated and always gives colour samples.
bool farFrom(const core::Isometry& T_W_reference, const core::Isometry& T_W_C) {
  return !core::posesNear(T_W_reference, T_W_C, 0.05, 3.0);
}

}  // namespace

SourceStage::SourceStage(core::FrameSource& source, std::optional<std::size_t> max_frames,
                         const std::atomic<bool>* stop, std::size_t skip_frames)
    : source_(source), max_frames_(max_frames), stop_(stop), skip_frames_(skip_frames) {
  figures_.live = source.isLive();
}

std::optional<core::Frame> SourceStage::next() {
  std::optional<core::Frame> frame = read();
  if (!frame) {
    source_.stopStreaming();
    figures_.live_stats = source_.liveStats();
  }
  return frame;
}

std::optional<core::Frame> SourceStage::read() {
  while (!max_frames_ || frames_read_ < *max_frames_) {
    if (stop_ != nullptr && stop_->load()) {
      figures_.stopped_on_request = true;
      spdlog::info("{}: stopped on request after {} frames", source_.name(), frames_read_);
      return std::nullopt;
    }
    core::ReadResult result;
    {
      ScopedStageTime time(timer_);
      result = source_.read();
    }
    if (source_.isLive()) frames_dropped_so_far_ = source_.liveStats().frames_dropped;
    switch (result.status) {
      case core::ReadStatus::kFrame:
        if (skip_frames_ > 0) {
          --skip_frames_;
          continue;
        }
        ++frames_read_;
        return std::move(result.frame);
      case core::ReadStatus::kBadFrame:
        // Skipped frames are positions in the source, readable or not: --skip-frames N starts
        // at the frame numbered N (a saved map's last_frame + 1 resumes after it).
        if (skip_frames_ > 0) {
          --skip_frames_;
          continue;
        }
        ++figures_.frames_bad;
        spdlog::warn("{}: skipped {}", source_.name(), result.problem);
        break;
      case core::ReadStatus::kInterrupted: {
        spdlog::warn("{}; finalizing the patches seen so far", result.problem);
        core::Frame marker;
        marker.source_interrupted = true;
        marker.index = frames_read_;
        return marker;
      }
      case core::ReadStatus::kEndOfData:
        if (!result.problem.empty()) {
          figures_.end_problem = result.problem;
          // Sources that name themselves in the message (recordings do) are not named twice.
          if (result.problem.rfind(source_.name(), 0) == 0) {
            spdlog::error("{}", result.problem);
          } else {
            spdlog::error("{}: {}", source_.name(), result.problem);
          }
        }
        return std::nullopt;
    }
  }
  return std::nullopt;
}

TrackingStage::TrackingStage(const fusion::TrackerConfig& tracker, PoseSource poses)
    : tracker_(tracker), poses_(poses) {
  figures_.poses = poses == PoseSource::kTrack ? "track" : "gt";
}

void TrackingStage::continueMap(const std::vector<fusion::MapKeyframe>& keyframes) {
  figures_.continued_map_keyframes = keyframes.size();
  if (poses_ != PoseSource::kTrack || keyframes.empty()) return;
  tracker_.continueMap(keyframes);
  awaiting_map_ = true;
}

std::optional<core::Isometry> TrackingStage::poseOf(
    const core::Frame& frame, std::string& problem,
    std::vector<std::shared_ptr<const fusion::KeyframeRecord>>& new_keyframes) {
  if (poses_ == PoseSource::kGroundTruth) {
    if (!frame.T_W_C_gt) problem = "no ground-truth pose (--poses gt)";
    return frame.T_W_C_gt;
  }
  // Tracking starts where the ground truth says, when there is one, so that the map and the
  // ground truth share a world frame.
  const fusion::TrackingResult tracked =
      tracker_.track(frame, frame.T_W_C_gt.value_or(core::Isometry::Identity()));
  if (tracked.status == fusion::TrackingStatus::kLost) {
    ++figures_.tracking_losses;
    problem = "tracking lost: " + tracked.problem;
    return std::nullopt;
  }
  for (const auto& keyframe : tracked.new_keyframes) {
    keyframe_ns_ = keyframe->timestamp_ns;
    ++figures_.keyframes_made;
    if (keyframe->relocalisation) ++figures_.relocalisation_keyframes;
  }
  new_keyframes = tracked.new_keyframes;
  if (awaiting_map_) {
    awaiting_map_ = false;
    if (tracked.status == fusion::TrackingStatus::kRelocalised) {
      figures_.continued_map_found_at_frame = frame.index;
      spdlog::info("frame {}: found in the continued map; this session maps in its frame",
                   frame.index);
      return tracked.T_W_C;
    }
    spdlog::warn("frame {}: {}; the saved map's patches are set aside", frame.index,
                 tracked.problem);
    own_frame_ = true;
  }
  if (tracked.from_features) ++figures_.feature_poses;
  if (tracked.status == fusion::TrackingStatus::kRelocalised) {
    ++figures_.relocalisations;
    spdlog::info("frame {}: relocalised against a recent keyframe", frame.index);
  }
  if (tracked.status == fusion::TrackingStatus::kRestarted) {
    ++figures_.tracking_restarts;
    spdlog::warn("frame {}: tracking restarted after {} lost frames", frame.index,
                 figures_.tracking_losses);
  }
  return tracked.T_W_C;
}

void TrackingStage::followLoopClosure() {
  if (poses_ == PoseSource::kTrack) tracker_.leaveCoverToLoopClosure();
}

void TrackingStage::forgetKeyframes(const std::vector<std::int64_t>& timestamps_ns) {
  if (poses_ != PoseSource::kTrack) return;
  figures_.relocalisation_keyframes -= tracker_.forgetKeyframes(timestamps_ns);
}

TrackedFrame TrackingStage::process(core::Frame frame) {
  TrackedFrame tracked;
  if (frame.source_interrupted) {
    // The camera may move while the device is away: the next frame is relocalised.
    if (poses_ == PoseSource::kTrack) tracker_.sourceInterrupted();
    tracked.skip_reason = "the source was interrupted";
    tracked.frame = std::move(frame);
    return tracked;
  }
  {
    ScopedStageTime time(timer_);
    try {
      if (frame.colour_camera) frame = core::withRegisteredColour(std::move(frame));
      tracked.T_W_C = poseOf(frame, tracked.skip_reason, tracked.new_keyframes);
      tracked.own_frame = own_frame_ && tracked.T_W_C.has_value();
      if (tracked.own_frame) own_frame_ = false;
      tracked.keyframe_ns = keyframe_ns_;
    } catch (const core::Error& e) {
      tracked.T_W_C.reset();
      tracked.skip_reason = e.what();
      spdlog::warn("tracking skipped {}", e.what());
    }
  }
  tracked.figures.tracking_ms = timer_.lastMs();
  tracked.frame = std::move(frame);
  return tracked;
}

IntegrationStage::IntegrationStage(const fusion::TsdfConfig& tsdf, int thread_cap,
                                   int holdout_every)
    : map_(tsdf) {
  figures_.holdout_every = holdout_every;
  map_.setThreadCap(thread_cap);
}

bool LoadShedding::late(std::int64_t arrival_ns) const {
  return after_ms > 0.0 && arrival_ns > 0 &&
         static_cast<double>(core::steadyNowNs() - arrival_ns) > after_ms * 1e6;
}

bool IntegrationStage::wantsFrame(const core::Isometry& T_W_C, std::int64_t arrival_ns) {
  ++posed_since_integrated_;
  const int every = map_.config().integrate_every_n_frames;
  const bool far = last_integrated_pose_ && farFrom(*last_integrated_pose_, T_W_C);
  bool wanted = !last_integrated_pose_ || posed_since_integrated_ >= every || far;
  // A moved camera sees new surface, so only an integration due by count waits for a frame
  // that is not late.
  if (wanted && last_integrated_pose_ && !far &&
      posed_since_integrated_ < every + LoadShedding::kMaxInARow && shedding_.late(arrival_ns)) {
    ++figures_.frames_shed;
    wanted = false;
  }
  if (wanted) {
    last_integrated_pose_ = T_W_C;
    posed_since_integrated_ = 0;
  }
  return wanted;
}

bool IntegrationStage::holdsApart(const TrackedFrame& tracked) {
  if (!hold_apart_) return false;
  for (const auto& keyframe : tracked.new_keyframes) {
    if (keyframe->starts_segment && seen_keyframe_) {
      if (keyframe->found_in_continued_map) {
        apart_since_.reset();  // in the map's frame already
      } else {
        apart_since_ = {keyframe->timestamp_ns, tracked.frame.index};
      }
    }
    seen_keyframe_ = true;
  }
  if (!apart_since_) return false;
  // Joined once the correction followed knows the segment's first keyframe and puts it in the
  // map; a correction older than that keyframe knows nothing of it yet.
  const loop::MapCorrection* correction = loop_correction_.get();
  if (correction != nullptr &&
      std::binary_search(correction->keyframe_ns.begin(), correction->keyframe_ns.end(),
                         apart_since_->first) &&
      correction->inMap(apart_since_->first)) {
    spdlog::info(
        "frame {}: the tracking segment begun at frame {} is joined to the map; its "
        "frames are fused from here",
        tracked.frame.index, apart_since_->second);
    apart_since_.reset();
    return false;
  }
  return true;
}

FusedFrame IntegrationStage::process(TrackedFrame tracked) {
  const bool apart = holdsApart(tracked);  // before its keyframes move on
  FusedFrame fused;
  fused.T_W_C = tracked.T_W_C;
  fused.keyframe_ns = tracked.keyframe_ns;
  fused.new_keyframes = std::move(tracked.new_keyframes);
  fused.own_frame = tracked.own_frame;
  fused.skip_reason = std::move(tracked.skip_reason);
  fused.figures = tracked.figures;
  if (tracked.frame.source_interrupted) {
    fused.frame = std::move(tracked.frame);
    return fused;
  }
  if (!apart && core::isHeldOut(tracked.frame.index, figures_.holdout_every)) {
    // Posed (the trajectory keeps it, for the view evaluation) but not part of the map.
    fused.held_out = true;
    if (fused.T_W_C) fused.skip_reason = "held out for evaluation (--holdout-every)";
    ++figures_.frames_held_out;
    fused.figures.tsdf_bytes = map_.memoryBytes();
    fused.frame = std::move(tracked.frame);
    return fused;
  }
  if (apart && fused.T_W_C) {
    fused.held_apart = true;
    fused.skip_reason = fmt::format(
        "held apart: the tracking segment begun at frame {} (a restart, or a relocalisation "
        "against an earlier segment) is not joined to the map yet (loop closure)",
        apart_since_->second);
    ++figures_.frames_held_apart;
    // Kept for the TSDF fused again at the end, which takes it if the segment is joined by then.
    if (log_ && fused.keyframe_ns && fused.keyframe_ns != last_logged_keyframe_ns_) {
      log_->keep(tracked.frame, *fused.T_W_C, *fused.keyframe_ns);
      last_logged_keyframe_ns_ = fused.keyframe_ns;
    }
    fused.figures.tsdf_bytes = map_.memoryBytes();
    fused.frame = std::move(tracked.frame);
    return fused;
  }
  if (fused.T_W_C && !wantsFrame(*fused.T_W_C, tracked.frame.arrival_ns)) {
    fused.between_integrations = true;
    ++figures_.frames_between_integrations;
    fused.figures.tsdf_bytes = map_.memoryBytes();
    fused.frame = std::move(tracked.frame);
    return fused;
  }
  {
    ScopedStageTime time(timer_);
    try {
      if (fused.T_W_C) {
        const core::Isometry T_W_C_map =
            loop_correction_
                ? loop_correction_->at(fused.keyframe_ns.value_or(tracked.frame.timestamp_ns)) *
                      *fused.T_W_C
                : *fused.T_W_C;
        map_.integrate(tracked.frame, T_W_C_map);
        fused.integrated = true;
        if (log_ && fused.keyframe_ns && fused.keyframe_ns != last_logged_keyframe_ns_) {
          log_->keep(tracked.frame, *fused.T_W_C, *fused.keyframe_ns);
          last_logged_keyframe_ns_ = fused.keyframe_ns;
        }
        if (const double distance_m = map_.config().release_distance_m; distance_m > 0.0) {
          const std::size_t released = map_.releaseBlocksBehind(T_W_C_map, distance_m);
          fused.figures.tsdf_blocks_released = released;
          figures_.tsdf_blocks_released += released;
        }
      }
    } catch (const core::Error& e) {
      fused.T_W_C.reset();
      fused.skip_reason = e.what();
      spdlog::warn("fusion skipped {}", e.what());
    }
  }
  fused.figures.integration_ms = timer_.lastMs();
  if (fused.integrated && tracked.frame.arrival_ns > 0) {
    fused.figures.latency_ms =
        static_cast<double>(core::steadyNowNs() - tracked.frame.arrival_ns) / 1e6;
  }
  (fused.integrated ? figures_.frames_integrated : figures_.frames_without_pose)++;
  fused.figures.tsdf_bytes = map_.memoryBytes();
  fused.frame = std::move(tracked.frame);
  return fused;
}

void IntegrationStage::keepFramesForCorrection(const std::filesystem::path& dir) {
  log_ = std::make_unique<fusion::ReintegrationLog>(dir, map_.config().integration_scale);
}

fusion::SurfaceMesh IntegrationStage::takeSurface() {
  fusion::SurfaceMesh surface = map_.extractMesh();
  bytes_when_taken_ = map_.memoryBytes();
  map_.clear();
  return surface;
}

IntegrationFigures IntegrationStage::figures() const {
  IntegrationFigures figures = figures_;
  figures.tsdf_bytes = bytes_when_taken_ ? *bytes_when_taken_ : map_.memoryBytes();
  return figures;
}

PlaneStage::PlaneStage(const planes::PlaneDetectorConfig& detector,
                       const planes::PatchMapConfig& patches,
                       const planes::PlaneAlignmentConfig& alignment, bool follows_loops)
    : detector_(detector), map_(patches), alignment_(alignment), follows_loops_(follows_loops) {}

bool PlaneStage::wantsColours(std::uint64_t index, const core::Isometry& T_W_C) const {
  const auto every = static_cast<std::uint64_t>(map_.config().colour_every_n_frames);
  if (!last_colour_pose_ || index % every == 0) return true;
  return farFrom(*last_colour_pose_, T_W_C);
}

std::optional<core::Isometry> PlaneStage::colourPose(const core::Frame& frame,
                                                     const core::Isometry& T_W_C,
                                                     const core::Isometry& T_W_C_map) {
  std::optional<core::Isometry> pose;
  if (map_.config().colour_at_colour_time && !frame.colour_timestamp_ns && !said_no_colour_time_) {
    spdlog::info(
        "frame {}: the source gives no colour time stamps; colour is placed at the depth "
        "image's pose",
        frame.index);
    said_no_colour_time_ = true;
  }
  if (map_.config().colour_at_colour_time && frame.colour_timestamp_ns && previous_pose_) {
    const auto& [previous_ns, T_W_previous] = *previous_pose_;
    const auto span = static_cast<double>(frame.timestamp_ns - previous_ns);
    const auto lead = static_cast<double>(*frame.colour_timestamp_ns - frame.timestamp_ns);
    // Beyond these the motion between frames says little about the motion at the colour's time.
    constexpr double kMaxSpanNs = 0.2e9, kMaxLeadNs = 0.1e9;
    if (span > 0.0 && span <= kMaxSpanNs && lead != 0.0 && std::abs(lead) <= kMaxLeadNs) {
      // T(t) = T_previous M^a, a = (t - t_previous) / span, with M the motion between the two
      // frames in the previous camera's frame; at the colour's time T = T_W_C M^(lead / span).
      const core::Isometry motion = T_W_previous.inverse() * T_W_C;
      pose = T_W_C_map * core::interpolate(core::Isometry::Identity(), motion, lead / span);
    }
  }
  previous_pose_ = {frame.timestamp_ns, T_W_C};
  return pose;
}

bool PlaneStage::shedsPlaneSearch(std::int64_t arrival_ns) {
  if (searches_shed_in_a_row_ < LoadShedding::kMaxInARow && shedding_.late(arrival_ns)) {
    ++searches_shed_in_a_row_;
    ++figures_.plane_searches_shed;
    return true;
  }
  searches_shed_in_a_row_ = 0;
  return false;
}

std::optional<Eigen::Vector3f> PlaneStage::sampleColours(
    const core::Frame& frame, const planes::PlaneDetection& detection, const core::Isometry& T_W_C,
    std::vector<int> ids, const std::optional<core::Isometry>& T_W_C_colour) {
  bool wanted = colour_shed_in_a_row_ > 0 || wantsColours(frame.index, T_W_C);
  if (wanted && colour_shed_in_a_row_ < LoadShedding::kMaxInARow &&
      shedding_.late(frame.arrival_ns)) {
    ++colour_shed_in_a_row_;
    ++figures_.colour_frames_shed;
    wanted = false;
  }
  if (wanted) {
    last_colour_pose_ = T_W_C;
    colour_shed_in_a_row_ = 0;
  } else {
    // A skipped frame still colours the patches that have hardly any colour yet (new ones),
    // so that no patch is left without samples.
    constexpr std::size_t kFewSamples = 2000;
    for (int& id : ids) {
      const planes::Patch* patch = map_.find(id);
      if (patch == nullptr || patch->samples->size() >= kFewSamples) id = -1;
    }
  }
  return map_.addColours(frame, detection, T_W_C, ids, sharpness_.measure(frame.rgb), T_W_C_colour);
}

void PlaneStage::count(const std::vector<planes::PatchEvent>& events) {
  for (const planes::PatchEvent& event : events) {
    if (event.kind == planes::PatchEvent::Kind::kFinalized) {
      ++figures_.patch_finalizations;
      ++figures_.finalizations_by_reason[event.reason];
    } else {
      ++figures_.patches_retired;
    }
  }
}

FusedFrame PlaneStage::process(FusedFrame fused) {
  if (fused.own_frame) {
    spdlog::warn("{} planes of the saved map set aside: this session's regions do not join them",
                 map_.setAsideAll());
  }
  if (fused.frame.source_interrupted) {
    // What was seen before the interruption is kept even if the device never comes back.
    fused.patch_events = finish();
    fused.finalized_patches = snapshotsOf(fused.patch_events);
    fused.figures.patches_live = map_.liveCount();
    fused.figures.patches_finalized = map_.finalizedCount();
    return fused;
  }
  if (fused.held_out) {
    // Only the pose, corrected as the frames around it are; the map does not see the frame.
    if (fused.T_W_C) fused.T_W_C_planes = correction_ * *fused.T_W_C;
    fused.figures.patches_live = map_.liveCount();
    fused.figures.patches_finalized = map_.finalizedCount();
    return fused;
  }
  bool searched = true;
  {
    ScopedStageTime time(timer_);
    try {
      followLoopClosure(fused.loop_correction);
      const bool posed = (fused.integrated || fused.between_integrations) && fused.T_W_C;
      if (posed && shedsPlaneSearch(fused.frame.arrival_ns)) {
        // Posed as the frames around it; the map does not see the frame.
        fused.T_W_C_planes = correction_ * *fused.T_W_C;
        searched = false;
      } else if (posed) {
        // The tracked pose, corrected for the drift measured against the patches so far; the
        // map holds it moved on by loop closure.
        fused.T_W_C_planes = correction_ * *fused.T_W_C;
        // Only with loop closure do the planes keep which keyframes saw them.
        const std::optional<std::int64_t> keyframe_ns =
            follows_loops_ ? fused.keyframe_ns : std::nullopt;
        const core::Isometry loop = keyframe_ns ? loopMotion(*keyframe_ns)
                                                : core::Isometry::Identity();
        const planes::PlaneDetection detection = detector_.detect(fused.frame);
        fused.figures.planes_detected = detection.planes.size();
        std::vector<planes::PlaneObservation> observations =
            planes::observationsOf(fused.frame, detection, loop * *fused.T_W_C_planes);
        if (const auto D = planes::alignToPatches(
                map_, observations, (loop * *fused.T_W_C_planes).translation(), alignment_)) {
          const core::Isometry D_tracked = loop.inverse() * *D * loop;  // in the tracker's world
          correction_ = D_tracked * correction_;
          fused.T_W_C_planes = D_tracked * *fused.T_W_C_planes;
          for (auto& observation : observations) {
            for (auto& X : observation.points_W) X = *D * X;
          }
        }
        for (auto& observation : observations) {
          observation.keyframe_ns = keyframe_ns;
          observation.loop_motion = loop;
        }
        const core::Isometry T_W_C_map = loop * *fused.T_W_C_planes;
        const std::optional<core::Isometry> T_W_C_colour =
            colourPose(fused.frame, *fused.T_W_C, T_W_C_map);
        fused.colour_gain =
            sampleColours(fused.frame, detection, T_W_C_map, map_.add(observations), T_W_C_colour);
      }
    } catch (const core::Error& e) {
      spdlog::warn("plane detection skipped {}", e.what());
    }
    // A frame the map did not see counts neither as seen nor as out of view.
    if (searched) fused.patch_events = map_.endFrame(static_cast<long>(fused.frame.index));
  }
  count(fused.patch_events);
  fused.finalized_patches = snapshotsOf(fused.patch_events);
  map_.releaseIdleSamples(static_cast<long>(fused.frame.index));
  fused.figures.colour_sample_bytes = colourSampleBytes();
  fused.figures.planes_ms = timer_.lastMs();
  fused.figures.patches_live = map_.liveCount();
  fused.figures.patches_finalized = map_.finalizedCount();
  return fused;
}

PlaneFigures PlaneStage::figures() const {
  PlaneFigures figures = figures_;
  figures.patches_finalized = map_.finalizedCount();
  for (const planes::Patch& patch : map_.patches()) figures.colour_samples += patch.samples->size();
  figures.colour_sample_bytes = colourSampleBytes();
  figures.samples_released = map_.samplesReleased();
  figures.loop_tiles_moved_within_planes = map_.tilesMovedWithinPlanes();
  return figures;
}

void PlaneStage::followLoopClosure(std::shared_ptr<const loop::MapCorrection> newest) {
  if (!follows_loops_) return;
  if (!newest || (loop_correction_ && newest->generation == loop_correction_->generation)) {
    if (map_.withinPlaneMovesPending()) continueMovesWithinPlanes();
    return;
  }
  loop_correction_ = std::move(newest);
  const auto start = std::chrono::steady_clock::now();
  const std::size_t tiles_before = map_.tilesMovedWithinPlanes();
  const std::size_t moved = map_.followCorrection(
      [this](std::int64_t keyframe_ns) { return loop_correction_->at(keyframe_ns); });
  // Planes that now coincide merge once every move within them is made, as below when some
  // are left for the next frames.
  const std::size_t merged = map_.withinPlaneMovesPending() ? 0 : map_.mergeCoinciding();
  const double ms = countFollowMs(start);
  const std::size_t tiles = map_.tilesMovedWithinPlanes() - tiles_before;
  ++figures_.loop_corrections_followed;
  figures_.loop_planes_moved += moved;
  figures_.loop_planes_merged += merged;
  spdlog::info(
      "loop closure: the map followed optimisation {}: {} planes moved ({} tiles within their "
      "plane{}), {} merged, in {:.0f} ms",
      loop_correction_->generation, moved, tiles,
      map_.withinPlaneMovesPending() ? ", more over the next frames" : "", merged, ms);
}

void PlaneStage::continueMovesWithinPlanes() {
  const auto start = std::chrono::steady_clock::now();
  const std::size_t tiles = map_.moveWithinPlanes();
  // The moved planes may now continue older ones.
  const std::size_t merged = map_.withinPlaneMovesPending() ? 0 : map_.mergeCoinciding();
  const double ms = countFollowMs(start);
  figures_.loop_planes_merged += merged;
  spdlog::debug(
      "loop closure: {} more tiles moved within their planes, {} planes merged, in "
      "{:.0f} ms{}",
      tiles, merged, ms, map_.withinPlaneMovesPending() ? "" : " (all moved)");
}

double PlaneStage::countFollowMs(std::chrono::steady_clock::time_point start) {
  const double ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  figures_.loop_follow_ms += ms;
  figures_.loop_follow_frame_ms_max = std::max(figures_.loop_follow_frame_ms_max, ms);
  return ms;
}

core::Isometry PlaneStage::loopMotion(std::int64_t keyframe_ns) const {
  return loop_correction_ ? loop_correction_->at(keyframe_ns) : core::Isometry::Identity();
}

std::vector<planes::PatchEvent> PlaneStage::finishStream(
    std::shared_ptr<const loop::MapCorrection> last_correction) {
  followLoopClosure(std::move(last_correction));
  return finish();
}

std::vector<planes::PatchEvent> PlaneStage::finish() {
  // Moves a correction left for later are made, and what then coincides merges, before the
  // last finalizations (an interrupted source ends here too).
  while (map_.withinPlaneMovesPending()) continueMovesWithinPlanes();
  std::vector<planes::PatchEvent> events = map_.finalizeAll();
  count(events);
  return events;
}

std::vector<planes::PatchSnapshot> PlaneStage::snapshotsOf(
    const std::vector<planes::PatchEvent>& events) const {
  return snapshots(planes::finalizedIds(events));
}

std::size_t PlaneStage::colourSampleBytes() const {
  std::size_t bytes = 0;
  for (const planes::Patch& patch : map_.patches()) bytes += patch.samples->bytes();
  return bytes;
}

std::vector<planes::PatchSnapshot> PlaneStage::snapshots(const std::vector<int>& ids) const {
  std::vector<planes::PatchSnapshot> out;
  // cv::Mat's move may throw, so a vector of snapshots copies them as it grows: reserve.
  out.reserve(ids.size());
  for (const int id : ids) {
    if (const planes::Patch* patch = map_.find(id)) out.push_back(map_.snapshot(*patch));
  }
  return out;
}

}  // namespace tessera::pipeline
