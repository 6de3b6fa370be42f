#include "tessera/pipeline/stages.h"

#include <unistd.h>

#include <chrono>
#include <fstream>

#include <fmt/format.h>
#include <spdlog/spdlog.h>
#include <nlohmann/json.hpp>

#include "tessera/core/clock.h"
#include "tessera/core/error.h"
#include "tessera/core/registration.h"
#include "tessera/core/trajectory.h"
#include "tessera/pipeline/texture_db_stages.h"
#include "tessera/texture/bitmap_export.h"

namespace tessera::pipeline {

namespace {

// A frame this far from a reference one (5 cm or 3 degrees: a recording of sparse keyframes,
// dropped frames) is always integrated and always gives colour samples.
bool farFrom(const core::Isometry& T_W_reference, const core::Isometry& T_W_C) {
  const core::Isometry motion = T_W_reference.inverse() * T_W_C;
  return motion.translation().norm() > 0.05 || core::rotationAngleDeg(motion) > 3.0;
}

}  // namespace

SourceStage::SourceStage(core::FrameSource& source, std::optional<std::size_t> max_frames,
                         const std::atomic<bool>* stop)
    : source_(source), max_frames_(max_frames), stop_(stop) {}

std::optional<core::Frame> SourceStage::next() {
  std::optional<core::Frame> frame = read();
  if (!frame) {
    source_.stopStreaming();
    live_stats_at_end_ = source_.liveStats();
  }
  return frame;
}

std::optional<core::Frame> SourceStage::read() {
  while (!max_frames_ || frames_read_ < *max_frames_) {
    if (stop_ != nullptr && stop_->load()) {
      stopped_on_request_ = true;
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
        ++frames_read_;
        return std::move(result.frame);
      case core::ReadStatus::kBadFrame:
        ++bad_frames_;
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
          end_problem_ = result.problem;
          spdlog::error("{}: {}", source_.name(), result.problem);
        }
        return std::nullopt;
    }
  }
  return std::nullopt;
}

TrackingStage::TrackingStage(const fusion::TrackerConfig& tracker, PoseSource poses,
                             loop::LoopCloser* loop_closer)
    : tracker_(tracker), poses_(poses), loop_closer_(loop_closer) {}

std::optional<core::Isometry> TrackingStage::poseOf(const core::Frame& frame,
                                                    std::string& problem) {
  if (poses_ == PoseSource::kGroundTruth) {
    if (!frame.T_W_C_gt) problem = "no ground-truth pose (--poses gt)";
    return frame.T_W_C_gt;
  }
  // Tracking starts where the ground truth says, when there is one, so that the map and the
  // ground truth share a world frame.
  const fusion::TrackingResult tracked =
      tracker_.track(frame, frame.T_W_C_gt.value_or(core::Isometry::Identity()));
  if (tracked.status == fusion::TrackingStatus::kLost) {
    ++tracking_losses_;
    problem = "tracking lost: " + tracked.problem;
    return std::nullopt;
  }
  for (const auto& keyframe : tracked.new_keyframes) {
    keyframe_ns_ = keyframe->timestamp_ns;
    if (loop_closer_) loop_closer_->add(keyframe);
  }
  if (tracked.from_features) ++feature_poses_;
  if (tracked.status == fusion::TrackingStatus::kRelocalised) {
    ++relocalisations_;
    spdlog::info("frame {}: relocalised against a recent keyframe", frame.index);
  }
  if (tracked.status == fusion::TrackingStatus::kRestarted) {
    ++tracking_restarts_;
    spdlog::warn("frame {}: tracking restarted after {} lost frames", frame.index,
                 tracking_losses_);
  }
  return tracked.T_W_C;
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
      tracked.T_W_C = poseOf(frame, tracked.skip_reason);
      tracked.keyframe_ns = keyframe_ns_;
    } catch (const core::Error& e) {
      tracked.T_W_C.reset();
      tracked.skip_reason = e.what();
      spdlog::warn("tracking skipped {}", e.what());
    }
  }
  tracked.tracking_ms = timer_.lastMs();
  tracked.frame = std::move(frame);
  return tracked;
}

IntegrationStage::IntegrationStage(const fusion::TsdfConfig& tsdf, int thread_cap,
                                   int holdout_every)
    : map_(tsdf), holdout_every_(holdout_every) {
  map_.setThreadCap(thread_cap);
}

bool IntegrationStage::wantsFrame(const core::Isometry& T_W_C) {
  ++posed_since_integrated_;
  const bool wanted = !last_integrated_pose_ ||
                      posed_since_integrated_ >= map_.config().integrate_every_n_frames ||
                      farFrom(*last_integrated_pose_, T_W_C);
  if (wanted) {
    last_integrated_pose_ = T_W_C;
    posed_since_integrated_ = 0;
  }
  return wanted;
}

FusedFrame IntegrationStage::process(TrackedFrame tracked) {
  FusedFrame fused;
  fused.T_W_C = tracked.T_W_C;
  fused.keyframe_ns = tracked.keyframe_ns;
  fused.skip_reason = std::move(tracked.skip_reason);
  fused.tracking_ms = tracked.tracking_ms;
  if (tracked.frame.source_interrupted) {
    fused.frame = std::move(tracked.frame);
    return fused;
  }
  if (core::isHeldOut(tracked.frame.index, holdout_every_)) {
    // Posed (the trajectory keeps it, for the view evaluation) but not part of the map.
    fused.held_out = true;
    if (fused.T_W_C) fused.skip_reason = "held out for evaluation (--holdout-every)";
    ++held_out_;
    fused.tsdf_bytes = map_.memoryBytes();
    fused.frame = std::move(tracked.frame);
    return fused;
  }
  if (fused.T_W_C && !wantsFrame(*fused.T_W_C)) {
    fused.between_integrations = true;
    ++between_integrations_;
    fused.tsdf_bytes = map_.memoryBytes();
    fused.frame = std::move(tracked.frame);
    return fused;
  }
  {
    ScopedStageTime time(timer_);
    try {
      if (fused.T_W_C) {
        map_.integrate(tracked.frame, *fused.T_W_C);
        fused.integrated = true;
        if (const double distance_m = map_.config().release_distance_m; distance_m > 0.0) {
          fused.tsdf_blocks_released = map_.releaseBlocksBehind(*fused.T_W_C, distance_m);
          blocks_released_ += fused.tsdf_blocks_released;
        }
      }
    } catch (const core::Error& e) {
      fused.T_W_C.reset();
      fused.skip_reason = e.what();
      spdlog::warn("fusion skipped {}", e.what());
    }
  }
  fused.integration_ms = timer_.lastMs();
  if (fused.integrated && tracked.frame.arrival_ns > 0) {
    fused.latency_ms = static_cast<double>(core::steadyNowNs() - tracked.frame.arrival_ns) / 1e6;
  }
  (fused.integrated ? integrated_ : skipped_)++;
  fused.tsdf_bytes = map_.memoryBytes();
  fused.frame = std::move(tracked.frame);
  return fused;
}

PlaneStage::PlaneStage(const planes::PlaneDetectorConfig& detector,
                       const planes::PatchMapConfig& patches,
                       const planes::PlaneAlignmentConfig& alignment,
                       loop::LoopCloser* loop_closer)
    : detector_(detector), map_(patches), alignment_(alignment), loop_closer_(loop_closer) {}

bool PlaneStage::wantsColours(std::uint64_t index, const core::Isometry& T_W_C) const {
  const auto every = static_cast<std::uint64_t>(map_.config().colour_every_n_frames);
  if (!last_colour_pose_ || index % every == 0) return true;
  return farFrom(*last_colour_pose_, T_W_C);
}

std::optional<Eigen::Vector3f> PlaneStage::sampleColours(const core::Frame& frame,
                                                         const planes::PlaneDetection& detection,
                                                         const core::Isometry& T_W_C,
                                                         std::vector<int> ids) {
  if (wantsColours(frame.index, T_W_C)) {
    last_colour_pose_ = T_W_C;
  } else {
    // A skipped frame still colours the patches that have hardly any colour yet (new ones),
    // so that no patch is left without samples.
    constexpr std::size_t kFewSamples = 2000;
    for (int& id : ids) {
      const planes::Patch* patch = map_.find(id);
      if (patch == nullptr || patch->samples.size() >= kFewSamples) id = -1;
    }
  }
  return map_.addColours(frame, detection, T_W_C, ids, sharpness_.measure(frame.rgb));
}

void PlaneStage::count(const std::vector<planes::PatchEvent>& events) {
  for (const planes::PatchEvent& event : events) {
    (event.kind == planes::PatchEvent::Kind::kFinalized ? finalizations_ : retirements_)++;
  }
}

FusedFrame PlaneStage::process(FusedFrame fused) {
  if (fused.frame.source_interrupted) {
    // What was seen before the interruption is kept even if the device never comes back.
    fused.patch_events = finish(fused.finalized_patches);
    fused.patches_live = map_.liveCount();
    fused.patches_finalized = map_.finalizedCount();
    return fused;
  }
  if (fused.held_out) {
    // Only the pose, corrected as the frames around it are; the map does not see the frame.
    if (fused.T_W_C) fused.T_W_C_planes = correction_ * *fused.T_W_C;
    fused.patches_live = map_.liveCount();
    fused.patches_finalized = map_.finalizedCount();
    return fused;
  }
  {
    ScopedStageTime time(timer_);
    try {
      followLoopClosure();
      if ((fused.integrated || fused.between_integrations) && fused.T_W_C) {
        // The tracked pose, corrected for the drift measured against the patches so far; the
        // map holds it moved on by loop closure.
        fused.T_W_C_planes = correction_ * *fused.T_W_C;
        // Only with loop closure do the planes keep which keyframes saw them.
        const std::optional<std::int64_t> keyframe_ns =
            loop_closer_ != nullptr ? fused.keyframe_ns : std::nullopt;
        const core::Isometry loop = keyframe_ns ? loopMotion(*keyframe_ns)
                                                : core::Isometry::Identity();
        const planes::PlaneDetection detection = detector_.detect(fused.frame);
        fused.planes_detected = detection.planes.size();
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
        fused.colour_gain = sampleColours(fused.frame, detection, loop * *fused.T_W_C_planes,
                                          map_.add(observations));
      }
    } catch (const core::Error& e) {
      spdlog::warn("plane detection skipped {}", e.what());
    }
    fused.patch_events = map_.endFrame(static_cast<long>(fused.frame.index));
  }
  count(fused.patch_events);
  fused.finalized_patches = snapshotsOf(fused.patch_events);
  map_.releaseIdleSamples(static_cast<long>(fused.frame.index));
  fused.planes_ms = timer_.lastMs();
  fused.patches_live = map_.liveCount();
  fused.patches_finalized = map_.finalizedCount();
  return fused;
}

void PlaneStage::followLoopClosure() {
  if (loop_closer_ == nullptr) return;
  std::shared_ptr<const loop::MapCorrection> newest = loop_closer_->correction();
  if (!newest || (loop_correction_ && newest->generation == loop_correction_->generation)) return;
  loop_correction_ = std::move(newest);
  const std::size_t moved = map_.followCorrection(
      [this](std::int64_t keyframe_ns) { return loop_correction_->at(keyframe_ns); });
  const std::size_t merged = map_.mergeCoinciding();
  ++corrections_followed_;
  planes_moved_ += moved;
  planes_merged_ += merged;
  spdlog::info("loop closure: the map followed optimisation {}: {} planes moved, {} merged",
               loop_correction_->generation, moved, merged);
}

core::Isometry PlaneStage::loopMotion(std::int64_t keyframe_ns) const {
  return loop_correction_ ? loop_correction_->at(keyframe_ns) : core::Isometry::Identity();
}

std::vector<planes::PatchEvent> PlaneStage::finishStream(
    std::vector<planes::PatchSnapshot>& finalized) {
  if (loop_closer_ != nullptr) {
    const auto start = std::chrono::steady_clock::now();
    loop_closer_->finish();
    loop_wait_s_ =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    followLoopClosure();
  }
  return finish(finalized);
}

std::vector<planes::PatchEvent> PlaneStage::finish(std::vector<planes::PatchSnapshot>& finalized) {
  std::vector<planes::PatchEvent> events = map_.finalizeAll();
  count(events);
  finalized = snapshotsOf(events);
  return events;
}

std::vector<planes::PatchSnapshot> PlaneStage::snapshotsOf(
    const std::vector<planes::PatchEvent>& events) const {
  std::vector<planes::PatchSnapshot> snapshots;
  for (const planes::PatchEvent& event : events) {
    if (event.kind != planes::PatchEvent::Kind::kFinalized) continue;
    if (const planes::Patch* patch = map_.find(event.id))
      snapshots.push_back(map_.snapshot(*patch));
  }
  return snapshots;
}

std::optional<texture::PatchBitmap> TextureStage::build(const planes::PatchSnapshot& patch) const {
  try {
    return texture::buildBitmap(patch, config_);
  } catch (const std::exception& e) {  // cv::Exception, bad_alloc: this patch goes untextured
    spdlog::warn("patch {} version {}: no bitmap: {}", patch.id, patch.version, e.what());
    return std::nullopt;
  }
}

void TextureStage::keep(std::optional<texture::PatchBitmap> built) {
  if (!built) return;
  texture::PatchBitmap& bitmap = *built;
  timer_.add(bitmap.build_ms);
  area_built_m2_ += bitmap.area_m2();
  // Versions of one patch come in finalization order (the commit stage's): the newest wins.
  const auto bytesOf = [](int width, int height) {
    return 3 * static_cast<std::size_t>(width) * static_cast<std::size_t>(height);
  };
  if (const auto it = written_.find(bitmap.id); it != written_.end()) {
    bitmap_bytes_ -= bytesOf(it->second.width, it->second.height);
    written_.erase(it);
  }
  if (const auto it = unwritten_.find(bitmap.id); it != unwritten_.end()) {
    bitmap_bytes_ -= bytesOf(it->second.grid.width, it->second.grid.height);
    unwritten_.erase(it);
  }
  bitmap_bytes_ += bytesOf(bitmap.grid.width, bitmap.grid.height);
  try {
    written_.emplace(bitmap.id, texture::writeBitmapFiles(bitmap, out_dir_));
  } catch (const core::Error& e) {  // kept, and tried again at the end
    spdlog::error("patch {} version {}: {}; its bitmap stays in memory", bitmap.id, bitmap.version,
                  e.what());
    unwritten_.emplace(bitmap.id, std::move(bitmap));
  }
}

void TextureStage::flush() {
  for (auto it = unwritten_.begin(); it != unwritten_.end(); it = unwritten_.erase(it)) {
    written_.emplace(it->first, texture::writeBitmapFiles(it->second, out_dir_));
  }
}

namespace {

// The process's resident memory now (/proc/self/statm: pages), MB; 0 where it cannot be read.
double residentMb() {
  std::ifstream statm("/proc/self/statm");
  std::size_t total_pages = 0, resident_pages = 0;
  if (!(statm >> total_pages >> resident_pages)) return 0.0;
  return static_cast<double>(resident_pages) * static_cast<double>(sysconf(_SC_PAGESIZE)) / 1e6;
}

}  // namespace

std::optional<double> StatsSink::rssGrowthMbPer1000Frames() const {
  const std::size_t n = rss_mb_.size();
  if (n < 200) return std::nullopt;
  // Least-squares slope of RSS against the frame count over the second half.
  double sx = 0, sy = 0, sxx = 0, sxy = 0, m = 0;
  for (std::size_t i = n / 2; i < n; ++i, ++m) {
    const auto x = static_cast<double>(i);
    sx += x;
    sy += rss_mb_[i];
    sxx += x * x;
    sxy += x * rss_mb_[i];
  }
  const double denominator = m * sxx - sx * sx;
  if (denominator <= 0.0) return std::nullopt;
  return 1000.0 * (m * sxy - sx * sy) / denominator;
}

StatsSink::StatsSink(const std::filesystem::path& out_dir, std::optional<std::size_t> frames_total,
                     ProgressCallback on_progress, std::function<std::size_t()> bitmap_bytes)
    : stats_path_(out_dir / "stats.jsonl"),
      trajectory_path_(out_dir / "trajectory.txt"),
      stats_(stats_path_),
      trajectory_(trajectory_path_),
      frames_total_(frames_total),
      on_progress_(std::move(on_progress)),
      bitmap_bytes_(std::move(bitmap_bytes)),
      start_(std::chrono::steady_clock::now()) {
  for (const auto& [file, path] :
       {std::pair{&stats_, &stats_path_}, {&trajectory_, &trajectory_path_}}) {
    if (!*file) throw core::Error(fmt::format("{}: cannot be created", path->string()));
  }
  trajectory_ << "# camera poses T_W_C of the map (tracked, corrected against the planes): "
                 "timestamp tx ty tz qx qy qz qw\n";
}

void StatsSink::process(const FusedFrame& fused) {
  ScopedStageTime time(timer_);
  std::lock_guard lock(write_mutex_);
  if (fused.frame.source_interrupted) {
    ++interruptions_;
    if (!write_failed_) {
      stats_ << nlohmann::json{{"type", "source"},
                               {"event", "interrupted"},
                               {"frames_done", frames_done_}}
                    .dump()
             << '\n';
      writePatchEvents(fused.patch_events);
    }
    return;
  }
  ++frames_done_;
  if (fused.latency_ms) latencies_ms_.push_back(*fused.latency_ms);
  // The map's pose of the frame: corrected against the patches when the plane stage did so.
  const std::optional<core::Isometry> pose = fused.T_W_C_planes ? fused.T_W_C_planes : fused.T_W_C;
  if (pose) estimate_[fused.frame.timestamp_ns] = *pose;
  if (fused.frame.T_W_C_gt) ground_truth_[fused.frame.timestamp_ns] = *fused.frame.T_W_C_gt;
  const std::size_t bitmap_bytes = bitmap_bytes_ ? bitmap_bytes_() : 0;
  map_bytes_ = fused.tsdf_bytes + bitmap_bytes;
  rss_mb_.push_back(residentMb());
  const double elapsed_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();

  if (!write_failed_) {
    nlohmann::json line = {{"type", "frame"},
                           {"index", fused.frame.index},
                           {"timestamp_ns", fused.frame.timestamp_ns},
                           {"elapsed_s", elapsed_s},
                           {"integrated", fused.integrated},
                           {"tracking_ms", fused.tracking_ms},
                           {"integration_ms", fused.integration_ms},
                           {"tsdf_bytes", fused.tsdf_bytes},
                           {"tsdf_blocks_released", fused.tsdf_blocks_released},
                           {"bitmap_bytes", bitmap_bytes},
                           {"map_bytes", map_bytes_},
                           {"rss_mb", rss_mb_.back()},
                           {"planes_ms", fused.planes_ms},
                           {"planes_detected", fused.planes_detected},
                           {"patches_live", fused.patches_live},
                           {"patches_finalized", fused.patches_finalized},
                           {"textures_stored", textures_stored_.load()}};
    if (!fused.integrated) line["skip_reason"] = fused.skip_reason;
    if (fused.latency_ms) line["latency_ms"] = *fused.latency_ms;
    if (fused.colour_gain) {
      line["colour_gain"] = {(*fused.colour_gain)[0], (*fused.colour_gain)[1],
                             (*fused.colour_gain)[2]};
    }
    stats_ << line.dump() << '\n';
    writePatchEvents(fused.patch_events);
    if (pose) trajectory_ << core::tumLine(fused.frame.timestamp_ns, *pose);
    if (!stats_ || !trajectory_) {
      write_failed_ = true;
      spdlog::error("{}: writing failed (disk full?); no further stats lines",
                    stats_path_.string());
    }
  }
  if (monitor_ != nullptr) {
    MonitorFrame frame;
    frame.elapsed_s = elapsed_s;
    frame.frames_done = frames_done_;
    frame.frames_total = frames_total_;
    frame.frames_dropped = frames_dropped_ ? frames_dropped_() : 0;
    frame.latency_ms = fused.latency_ms;
    frame.tracking_ms = fused.tracking_ms;
    frame.integration_ms = fused.integration_ms;
    frame.planes_ms = fused.planes_ms;
    frame.tsdf_bytes = fused.tsdf_bytes;
    frame.bitmap_bytes = bitmap_bytes;
    frame.map_bytes = map_bytes_;
    frame.patches_live = fused.patches_live;
    frame.patches_finalized = fused.patches_finalized;
    monitor_->onFrame(frame);
  }
  if (on_progress_) {
    on_progress_({frames_done_, frames_total_, elapsed_s, map_bytes_, fused.latency_ms});
  }
}

void StatsSink::attachMonitor(MapMonitor* monitor, std::function<std::size_t()> frames_dropped) {
  monitor_ = monitor;
  frames_dropped_ = std::move(frames_dropped);
}

void StatsSink::writePatchEvents(const std::vector<planes::PatchEvent>& events) {
  std::lock_guard lock(write_mutex_);
  for (const planes::PatchEvent& event : events) {
    const bool finalized = event.kind == planes::PatchEvent::Kind::kFinalized;
    nlohmann::json line = {{"type", "patch"},
                           {"event", finalized ? "finalized" : "retired"},
                           {"id", event.id},
                           {"version", event.version},
                           {"frames_done", frames_done_}};
    if (finalized) line["area_m2"] = event.area_m2;
    stats_ << line.dump() << '\n';
  }
}

void StatsSink::writeCommit(const CommitRecord& record, std::size_t batch, std::size_t batch_size,
                            std::uint64_t frame_index, const MonitorCommit& totals) {
  const std::size_t textures_stored = totals.textures_stored;
  if (monitor_ != nullptr) {
    MonitorCommit commit = totals;
    commit.committed = record.instance.has_value();
    commit.reused = record.instance && record.instance->reused;
    commit.bitmap_ms = record.bitmap_ms;
    commit.match_ms = record.match_ms;
    commit.commit_latency_ms = record.commit_latency_ms;
    commit.ccv_considered = record.ccv_considered;
    commit.ccv_removed = record.ccv_removed;
    monitor_->onCommit(commit);
  }
  std::lock_guard lock(write_mutex_);
  textures_stored_ = textures_stored;
  BatchCounts& counts = batches_[batch];
  counts.patches += 1;
  counts.considered += record.ccv_considered;
  counts.removed += record.ccv_removed;
  const bool reused = record.instance && record.instance->reused;
  counts.reuses += reused ? 1 : 0;
  if (write_failed_) return;
  if (record.patch_id != 0 || record.instance) {
    nlohmann::json line = {{"type", "patch"},
                           {"event", "committed"},
                           {"id", record.patch_id},
                           {"version", record.version},
                           {"frame", frame_index},
                           {"committed", record.instance.has_value()},
                           {"method", record.method},
                           {"ccv_considered", record.ccv_considered},
                           {"ccv_removed", record.ccv_removed},
                           {"bitmap_ms", record.bitmap_ms},
                           {"describe_ms", record.describe_ms},
                           {"match_ms", record.match_ms},
                           {"pattern_ms", record.pattern_ms},
                           {"commit_latency_ms", record.commit_latency_ms},
                           {"textures_stored", textures_stored}};
    if (record.instance) {
      const core::Similarity2& s = record.instance->transform;
      line["texture_id"] = record.instance->texture_id;
      line["reused"] = reused;
      line["transform"] = {s.a, s.b, s.tx, s.ty};
      line["psnr_db"] = record.instance->psnr_db ? nlohmann::json(*record.instance->psnr_db)
                                                 : nlohmann::json(nullptr);
      nlohmann::json overlays = nlohmann::json::array();
      for (const db::TextureInstance& overlay : record.overlays) {
        overlays.push_back({{"texture_id", overlay.texture_id}, {"reused", overlay.reused}});
      }
      line["overlays"] = overlays;
    }
    stats_ << line.dump() << '\n';
  }
  if (counts.patches == batch_size) {
    stats_ << nlohmann::json{{"type", "match"},
                             {"frame", frame_index},
                             {"patches", counts.patches},
                             {"ccv_considered", counts.considered},
                             {"ccv_removed", counts.removed},
                             {"reuses", counts.reuses}}
                  .dump()
           << '\n';
    batches_.erase(batch);
  }
}

void StatsSink::flush() {
  stats_.close();
  trajectory_.close();
  if (write_failed_ || stats_.fail() || trajectory_.fail()) {
    throw core::Error(fmt::format("{} or {}: could not be written completely (disk full?)",
                                  stats_path_.string(), trajectory_path_.string()));
  }
}

}  // namespace tessera::pipeline
