#pragma once
// The stages of `tessera run`, as plain classes with a narrow process()/flush() call.
// They know nothing of TBB: flow_graph.h wires them. Each stage is called from one node of the
// graph (a serial node, unless it says it is thread-safe), so none of them locks.
#include <atomic>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>

#include "tessera/core/frame_source.h"
#include "tessera/core/thinned_series.h"
#include "tessera/core/trajectory.h"
#include "tessera/fusion/reintegration_log.h"
#include "tessera/fusion/tracker.h"
#include "tessera/fusion/tsdf_map.h"
#include "tessera/loop/map_correction.h"
#include "tessera/pipeline/map_monitor.h"
#include "tessera/pipeline/stage_figures.h"
#include "tessera/pipeline/stage_timer.h"
#include "tessera/planes/frame_sharpness.h"
#include "tessera/planes/patch_map.h"
#include "tessera/planes/plane_alignment.h"
#include "tessera/planes/plane_detector.h"
#include "tessera/planes/texture_binding.h"
#include "tessera/texture/bitmap_builder.h"

namespace tessera::pipeline {

struct CommitMessage;  // texture_db_stages.h

// Pulls frames from a FrameSource; bad frames are counted, logged and skipped. An interrupted
// live source gives a marker frame (Frame::source_interrupted) so that the stages finalize
// what they have while the source waits for its device.
class SourceStage {
 public:
  // `stop`, when given, ends the stream as soon as it is set (Ctrl-C, SIGTERM).
  // The first `skip_frames` frames, readable or not, are read and dropped (a recording
  // replayed from the middle starts at the frame numbered skip_frames).
  SourceStage(core::FrameSource& source, std::optional<std::size_t> max_frames,
              const std::atomic<bool>* stop = nullptr, std::size_t skip_frames = 0);

  // The next good frame (or interruption marker), or nothing at the end of the stream.
  std::optional<core::Frame> next();

  std::size_t framesRead() const { return frames_read_; }
  // The live source's counts in it are those when its stream ended (a device keeps sending
  // after that).
  const SourceFigures& figures() const { return figures_; }
  // Frames a live source dropped up to its last read; safe to call from any thread.
  std::size_t framesDroppedSoFar() const { return frames_dropped_so_far_.load(); }
  const StageTimer& timer() const { return timer_; }

 private:
  std::optional<core::Frame> read();

  core::FrameSource& source_;
  std::optional<std::size_t> max_frames_;
  const std::atomic<bool>* stop_;
  std::size_t frames_read_ = 0;
  std::size_t skip_frames_ = 0;  // still to be dropped
  SourceFigures figures_;
  std::atomic<std::size_t> frames_dropped_so_far_{0};
  StageTimer timer_;
};

// Where fusion takes camera poses from.
enum class PoseSource {
  kTrack,        // estimated by the tracker (the first frame starts at its ground truth, if any)
  kGroundTruth,  // the recording's ground truth; frames without one are not integrated
};

// A frame with the pose it will be fused at, or why it has none.
struct TrackedFrame {
  core::Frame frame;                    // colour registered to depth
  std::optional<core::Isometry> T_W_C;  // nothing: do not integrate
  std::string skip_reason;
  FrameFigures figures;  // tracking_ms so far
  // The time of the last keyframe the tracker made at or before this frame: loop closure
  // corrects the frame's pose with that keyframe's.
  std::optional<std::int64_t> keyframe_ns;
  // Keyframes the tracker made at this frame, on their way to loop closure.
  std::vector<std::shared_ptr<const fusion::KeyframeRecord>> new_keyframes;
  // A continued map's first frames were not found in it: this session maps in its own frame,
  // and the earlier patches are set aside (planes::PatchMap::setAsideAll).
  bool own_frame = false;
};

// A frame after fusion, with what the sink reports about it.
struct FusedFrame {
  core::Frame frame;
  bool integrated = false;
  bool held_out = false;  // left out of fusion and texturing (run --holdout-every)
  // Tracked in a segment not yet joined to the map (IntegrationStage::holdApartUnjoinedSegments):
  // T_W_C is the tracker's pose, which is not in the map's frame.
  bool held_apart = false;
  bool own_frame = false;  // as TrackedFrame's
  // Posed and searched for planes, but not integrated (tsdf.integrate_every_n_frames).
  bool between_integrations = false;
  std::optional<core::Isometry> T_W_C;  // the pose it was fused at
  std::optional<std::int64_t> keyframe_ns;  // TrackedFrame::keyframe_ns
  std::vector<std::shared_ptr<const fusion::KeyframeRecord>> new_keyframes;  // ditto
  // With loop closure: its newest map correction when the frame reached the plane stage.
  std::shared_ptr<const loop::MapCorrection> loop_correction;
  std::string skip_reason;              // why the frame was not integrated
  FrameFigures figures;                 // the plane stage's too, once it is through
  // Filled by the plane stage.
  std::optional<core::Isometry> T_W_C_planes;  // the pose corrected against the patch map
  std::optional<Eigen::Vector3f> colour_gain;  // the frame's exposure gain, when it gave colour
  std::vector<planes::PatchEvent> patch_events;
  // A copy of each patch finalized in this frame, for the texturing stage.
  std::vector<planes::PatchSnapshot> finalized_patches;
};

// The map's pose of a frame: corrected against the patches when the plane stage did so.
inline std::optional<core::Isometry> mapPoseOf(const FusedFrame& fused) {
  if (fused.held_apart) return std::nullopt;
  return fused.T_W_C_planes ? fused.T_W_C_planes : fused.T_W_C;
}

// Registers colour to depth and gives each frame its pose: tracked, or the ground truth. A
// frame whose tracking is lost gets no pose, so it cannot corrupt the map.
class TrackingStage {
 public:
  // The keyframes the tracker makes go on with the frame (TrackedFrame::new_keyframes), to
  // loop closure when the run has it.
  TrackingStage(const fusion::TrackerConfig& tracker, PoseSource poses);

  TrackedFrame process(core::Frame frame);

  // An earlier session's keyframes (`tessera run --continue`): with tracked poses, the first
  // frames are relocalised against them (fusion::Tracker::continueMap).
  void continueMap(const std::vector<fusion::MapKeyframe>& keyframes);

  // The run closes loops: loop closure, at its corrected poses, decides which keyframes
  // revisit a kept one's place, and forgetKeyframes() passes its decisions on to the tracker
  // (fusion::Tracker::leaveCoverToLoopClosure).
  void followLoopClosure();
  void forgetKeyframes(const std::vector<std::int64_t>& timestamps_ns);

  const TrackingFigures& figures() const { return figures_; }
  const StageTimer& timer() const { return timer_; }

 private:
  // The frame's pose, or nothing with the `problem`; `new_keyframes` gets the keyframes the
  // tracker made at it.
  std::optional<core::Isometry> poseOf(
      const core::Frame& frame, std::string& problem,
      std::vector<std::shared_ptr<const fusion::KeyframeRecord>>& new_keyframes);

  fusion::Tracker tracker_;
  PoseSource poses_;
  TrackingFigures figures_;
  std::optional<std::int64_t> keyframe_ns_;  // the newest keyframe's time
  bool awaiting_map_ = false;                // continuing a map; no frame posed in it yet
  bool own_frame_ = false;                   // not found in it: the next posed frame says so
  StageTimer timer_;
};

// Live sources: work a frame can do without (an integration due by count alone, a colour
// sampling) is left out for a frame that reaches it more than `after_ms` after its arrival,
// and done on the next frame instead, so that a backlog clears rather than ends in dropped
// frames (docs/ROBOT.md, "When the CPU is short"). A replay's frames carry no arrival time and
// are never late.
struct LoadShedding {
  double after_ms = 0.0;  // 0: never
  // At most this many frames in a row leave the same work out.
  static constexpr int kMaxInARow = 2;
  bool late(std::int64_t arrival_ns) const;
};

// Integrates posed frames into the TSDF and releases blocks the camera has left far behind.
// Runs beside the tracking stage: frame N is integrated while frame N+1 is tracked.
class IntegrationStage {
 public:
  // Every holdout_every-th frame (core::isHeldOut) is posed but neither fused nor textured, so
  // that `tessera eval` can score views the map was not built from (0: none).
  IntegrationStage(const fusion::TsdfConfig& tsdf, int thread_cap, int holdout_every = 0);

  FusedFrame process(TrackedFrame tracked);

  const fusion::TsdfMap& map() const { return map_; }
  // The TSDF's surface, its volume freed (at the end of a run, before the volume is fused again
  // at corrected poses: the two volumes never hold memory at once). figures() then gives the
  // TSDF's size as it was.
  fusion::SurfaceMesh takeSurface();
  IntegrationFigures figures() const;

  // With loop closure: keeps the first integrated frame of each keyframe in a log under `dir`,
  // for the TSDF to be fused again at the corrected poses at the end.
  void keepFramesForCorrection(const std::filesystem::path& dir);
  void shedLoad(LoadShedding shedding) { shedding_ = shedding; }
  // With loop closure: after a tracking restart (a keyframe that starts a segment, the run's
  // first aside), frames are held apart until the correction followed says that segment is
  // joined to the first (loop::LoopConfig::hold_apart_unjoined_segments). Their first frame per
  // keyframe still goes to the log, so that the TSDF fused again at the end has them once
  // their segment is joined.
  void holdApartUnjoinedSegments() { hold_apart_ = true; }
  // With loop closure: frames are fused at their keyframe's corrected pose (the newest
  // correction given), so that a place seen again lands on what was fused there before instead
  // of beside it, drifted. The log keeps tracked poses: the correction at the end recomputes.
  void followLoopClosure(std::shared_ptr<const loop::MapCorrection> newest) {
    loop_correction_ = std::move(newest);
  }
  // The log, or null without it.
  const fusion::ReintegrationLog* reintegrationLog() const { return log_.get(); }
  const StageTimer& timer() const { return timer_; }

 private:
  // Whether the frame posed at T_W_C, arrived at `arrival_ns`, is integrated
  // (TsdfConfig::integrate_every_n_frames, LoadShedding).
  bool wantsFrame(const core::Isometry& T_W_C, std::int64_t arrival_ns);
  // Notes the segment the tracker restarted in at this frame; whether `tracked` is to be held
  // apart (its segment not yet joined to the map).
  bool holdsApart(const TrackedFrame& tracked);

  fusion::TsdfMap map_;
  std::unique_ptr<fusion::ReintegrationLog> log_;
  std::optional<std::int64_t> last_logged_keyframe_ns_;
  std::optional<core::Isometry> last_integrated_pose_;
  std::shared_ptr<const loop::MapCorrection> loop_correction_;
  bool hold_apart_ = false;
  bool seen_keyframe_ = false;  // the run's first keyframe starts the first segment
  // The keyframe time and frame at which the segment held apart began.
  std::optional<std::pair<std::int64_t, std::uint64_t>> apart_since_;
  int posed_since_integrated_ = 0;
  LoadShedding shedding_;
  IntegrationFigures figures_;  // all but tsdf_bytes, read from the map
  std::optional<std::size_t> bytes_when_taken_;  // the TSDF's size before takeSurface()
  StageTimer timer_;
};

// Finds the planar regions of each posed frame, grows the patch map with them and their
// colours, and finalizes patches that stopped growing or left the view. With loop closure
// (`follows_loops`) the map follows each new correction the frames bring
// (FusedFrame::loop_correction: PatchMap::followCorrection, its moves within planes spread
// over the next frames, then mergeCoinciding), and each frame's points are placed with the
// correction of its keyframe.
class PlaneStage {
 public:
  PlaneStage(const planes::PlaneDetectorConfig& detector, const planes::PatchMapConfig& patches,
             const planes::PlaneAlignmentConfig& alignment, bool follows_loops = false);

  FusedFrame process(FusedFrame fused);
  // Finalizes every remaining patch above the area bound (an interrupted source: what was seen
  // so far is kept); snapshots() copies them for texturing.
  std::vector<planes::PatchEvent> finish();
  // End of stream: follows loop closure's last correction (when there is one), then finish().
  std::vector<planes::PatchEvent> finishStream(
      std::shared_ptr<const loop::MapCorrection> last_correction = nullptr);
  // A copy of each patch of `ids` still in the map, for texturing.
  std::vector<planes::PatchSnapshot> snapshots(const std::vector<int>& ids) const;

  const planes::PatchMap& map() const { return map_; }
  // The loop correction the map follows now (none before the first).
  std::shared_ptr<const loop::MapCorrection> loopCorrection() const { return loop_correction_; }
  // Continues an earlier session's map (`tessera run --continue`), before the first frame.
  void continueMap(planes::PatchMap&& map) { map_ = std::move(map); }
  // Where finalized patches' colour samples go when they leave memory (PatchMap).
  void spillSamplesTo(std::filesystem::path dir) { map_.setSampleSpillDir(std::move(dir)); }
  void shedLoad(LoadShedding shedding) { shedding_ = shedding; }
  PlaneFigures figures() const;
  const StageTimer& timer() const { return timer_; }

 private:
  void count(const std::vector<planes::PatchEvent>& events);
  // Moves the map with `newest`, unless it is the correction it follows already.
  void followLoopClosure(std::shared_ptr<const loop::MapCorrection> newest);
  // Moves within planes a correction left for the frames after it (patches.
  // max_tiles_moved_per_frame), then merges what now coincides once none are left.
  void continueMovesWithinPlanes();
  // Adds the time since `start` to the figures of following corrections; returns it.
  double countFollowMs(std::chrono::steady_clock::time_point start);
  // The loop-closure motion of the keyframe at `keyframe_ns` (identity before any).
  core::Isometry loopMotion(std::int64_t keyframe_ns) const;
  std::vector<planes::PatchSnapshot> snapshotsOf(
      const std::vector<planes::PatchEvent>& events) const;
  // The patches' colour samples in memory (spilled ones are on disk).
  std::size_t colourSampleBytes() const;
  // Every N-th frame (patches.colour_every_n_frames), and any frame the camera has moved
  // more than 5 cm or 3 degrees from since the last one sampled.
  bool wantsColours(std::uint64_t index, const core::Isometry& T_W_C) const;
  // Colours of the regions that went to patches `ids`; on a frame not wanted for colour, only
  // for patches that have hardly any yet. Returns the frame's exposure gain (PatchMap).
  std::optional<Eigen::Vector3f> sampleColours(const core::Frame& frame,
                                               const planes::PlaneDetection& detection,
                                               const core::Isometry& T_W_C, std::vector<int> ids,
                                               const std::optional<core::Isometry>& T_W_C_colour);
  // The pose at the colour image's time stamp, where the source gives one and it differs from
  // the depth image's: the camera's motion from the previous frame to this one (tracked, or as
  // the ground truth has it) interpolated or carried on to that time, applied to T_W_C_map.
  // Remembers this frame's tracked pose T_W_C for the next.
  std::optional<core::Isometry> colourPose(const core::Frame& frame, const core::Isometry& T_W_C,
                                           const core::Isometry& T_W_C_map);
  // A late live frame leaves its plane search (and with it its colours) to the next frames,
  // at most LoadShedding::kMaxInARow in a row.
  bool shedsPlaneSearch(std::int64_t arrival_ns);

  planes::PlaneDetector detector_;
  planes::PatchMap map_;
  planes::SharpnessGauge sharpness_;
  std::optional<core::Isometry> last_colour_pose_;
  LoadShedding shedding_;
  int colour_shed_in_a_row_ = 0;  // > 0: the frames' colours are owed to the next frame
  int searches_shed_in_a_row_ = 0;
  std::optional<std::pair<std::int64_t, core::Isometry>> previous_pose_;  // time, tracked pose
  bool said_no_colour_time_ = false;
  planes::PlaneAlignmentConfig alignment_;
  // World drift measured against the patches, carried frame to frame, in the tracker's world
  // (before loop closure's motion).
  core::Isometry correction_ = core::Isometry::Identity();
  bool follows_loops_;
  std::shared_ptr<const loop::MapCorrection> loop_correction_;  // the one the map follows
  PlaneFigures figures_;  // the counts; the map's own figures are read from it
  StageTimer timer_;
};

// Keeps the newest version of each patch's bitmap, written under out_dir/textures/, after
// its commit (the commit node's).
class BitmapFiles {
 public:
  explicit BitmapFiles(std::filesystem::path out_dir) : out_dir_(std::move(out_dir)) {}

  // Writes the bitmap's files when it is the newest version of its patch, and lets its pixels
  // go (the map's memory stays bounded); one whose files cannot be written (disk full) stays
  // in memory until flush().
  void keep(std::optional<texture::PatchBitmap> bitmap);
  // Writes the bitmaps still in memory; throws core::Error naming a file that cannot be
  // written.
  void flush();

  // The run's folder, where the bitmaps' files are written.
  const std::filesystem::path& outDir() const { return out_dir_; }
  // Where the newest bitmap of each patch id lies on its patch, and its files.
  const planes::TextureBindings& written() const { return written_; }
  // The bitmaps of an earlier session whose map this run continues (their files are there).
  void adopt(const planes::TextureBindings& earlier);
  // The bindings of written() whose version is the one `versions` gives their patch, with
  // second names for their files under `dir` (the same names as under the run's folder):
  // a checkpoint of the map, safe while another thread keeps bitmaps. Throws core::Error
  // naming a file that cannot be linked or copied.
  planes::TextureBindings linkCurrentInto(const std::filesystem::path& dir,
                                          const std::map<int, int>& versions) const;
  // Build time of each bitmap, and their total area (m^2 of observed texels).
  const StageTimer& timer() const { return timer_; }
  double areaBuiltM2() const { return area_built_m2_; }
  // Bytes of the bitmaps kept (3 per texel of their grids); safe to read from any thread.
  std::size_t bitmapBytes() const { return bitmap_bytes_.load(); }

 private:
  std::filesystem::path out_dir_;
  mutable std::mutex written_mutex_;  // written_ changes on the committing thread
  planes::TextureBindings written_;
  std::map<int, texture::PatchBitmap> unwritten_;  // newest versions whose files failed
  std::atomic<std::size_t> bitmap_bytes_{0};
  StageTimer timer_;
  double area_built_m2_ = 0.0;
};

// What the sink tells a progress display after each frame.
struct Progress {
  std::size_t frames_done = 0;
  std::optional<std::size_t> frames_total;
  double elapsed_s = 0.0;
  std::size_t map_bytes = 0;
  std::optional<double> latency_ms;  // live sources: the last frame's capture-to-fusion time
};

// Writes one stats.jsonl line per frame and the poses frames were fused at (trajectory.txt,
// TUM format), and keeps the running totals.
class StatsSink {
 public:
  using ProgressCallback = std::function<void(const Progress&)>;

  // Creates OUT/stats.jsonl and OUT/trajectory.txt; throws core::Error naming a file that
  // cannot be created. `bitmap_bytes`, when given, says how much the patch bitmaps hold now:
  // they count towards the map's size.
  StatsSink(const std::filesystem::path& out_dir, std::optional<std::size_t> frames_total,
            ProgressCallback on_progress, std::function<std::size_t()> bitmap_bytes = {});

  void process(const FusedFrame& fused);
  // One stats.jsonl line per patch event: {"type":"patch","event":"finalized"|"retired",...}.
  void writePatchEvents(const std::vector<planes::PatchEvent>& events);
  // One line per committed patch ({"type":"patch","event":"committed",...}) and, once every
  // patch of its batch (the patches one frame finalized) is in, one {"type":"match",...} line
  // with the batch's CCV prefilter counts. The totals (the run's figures after this commit)
  // go to the monitor; textures_stored also into the lines.
  void writeCommit(const CommitMessage& commit);
  // Every frame and commit also updates `monitor` (may be null); `frames_dropped` says how many
  // frames a live source has dropped so far.
  void attachMonitor(MapMonitor* monitor, std::function<std::size_t()> frames_dropped);
  // Closes the files; throws core::Error naming one whose writing failed (disk full).
  void flush();

  StreamFigures figures() const;
  std::size_t mapBytes() const { return map_bytes_; }
  // The poses frames were fused at, and the recording's ground truth for the same frames.
  const core::Trajectory& estimate() const { return estimate_; }
  const core::Trajectory& groundTruth() const { return ground_truth_; }
  const StageTimer& timer() const { return timer_; }
  // The process's CPU time (core::processCpuSeconds) when the last frame was reported.
  double cpuAtLastFrameS() const { return cpu_last_frame_s_; }

 private:
  std::filesystem::path stats_path_;
  std::filesystem::path trajectory_path_;
  std::ofstream stats_;
  std::ofstream trajectory_;
  std::optional<std::size_t> frames_total_;
  ProgressCallback on_progress_;
  std::function<std::size_t()> bitmap_bytes_;
  MapMonitor* monitor_ = nullptr;
  std::function<std::size_t()> frames_dropped_;
  std::chrono::steady_clock::time_point start_;
  std::size_t frames_done_ = 0;
  std::size_t frames_without_pose_ = 0, frames_held_apart_ = 0;  // as IntegrationFigures'
  std::size_t map_bytes_ = 0;
  std::size_t interruptions_ = 0;
  core::Trajectory estimate_;
  core::Trajectory ground_truth_;
  core::Quantiles latencies_ms_;
  core::ThinnedSeries rss_mb_;                         // resident memory (MB) against frames done
  double cpu_start_s_ = 0.0, cpu_last_frame_s_ = 0.0;  // process CPU time
  double elapsed_last_frame_s_ = 0.0;
  bool write_failed_ = false;
  std::size_t textures_stored_ = 0;
  struct BatchCounts {
    std::size_t patches = 0, considered = 0, removed = 0, reuses = 0;
  };
  std::map<std::size_t, BatchCounts> batches_;
  StageTimer timer_;
};

}  // namespace tessera::pipeline
