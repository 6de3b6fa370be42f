#pragma once
// `tessera run`'s stages as the flow graph calls them (flow_graph.h): each call goes to the one
// stage that does the work. Loop closure is reached from here only: keyframes in, corrections
// out onto the frames. The commit also keeps the patch's bitmap and sums the run's totals for
// the report.
#include <chrono>

#include "tessera/loop/loop_closer.h"
#include "tessera/pipeline/flow_graph.h"
#include "tessera/pipeline/run_listener.h"

namespace tessera::pipeline::internal {

class CorrectedSurface;
class MapSaver;

// When freed memory goes back to the kernel (PipelineConfig::return_freed_memory_s and
// return_freed_memory_above_mb); 0 turns either off.
struct FreedMemoryReturn {
  double every_s = 0.0;   // after a commit, at most this often
  double above_mb = 0.0;  // after a frame, while resident memory is above this (at most 1/s)
};

class RunStages : public FramePath, public PatchPath, public RunReport {
 public:
  RunStages(SourceStage& source, TrackingStage& tracking, IntegrationStage& integration,
            PlaneStage& planes, const DescribeStage& describe, CommitStage& commit,
            BitmapFiles& bitmaps, StatsSink& sink, loop::LoopCloser* loop_closer,
            RunListener* listener, FreedMemoryReturn freed_memory_return = {},
            MapSaver* map_saver = nullptr, CorrectedSurface* surface = nullptr)
      : source_(source),
        tracking_(tracking),
        integration_(integration),
        planes_(planes),
        describe_(describe),
        commit_(commit),
        bitmaps_(bitmaps),
        sink_(sink),
        loop_closer_(loop_closer),
        listener_(listener),
        freed_memory_return_(freed_memory_return),
        map_saver_(map_saver),
        surface_(surface) {}

  std::optional<core::Frame> next() override { return source_.next(); }
  TrackedFrame track(core::Frame frame) override;
  FusedFrame integrate(TrackedFrame tracked) override {
    if (loop_closer_ != nullptr) integration_.followLoopClosure(loop_closer_->correction());
    return integration_.process(std::move(tracked));
  }
  FusedFrame closeLoops(FusedFrame fused) override;
  // Also the map's checkpoint, while the plane stage holds still.
  FusedFrame findPlanes(FusedFrame fused) override;
  // Waits for loop closure's last optimisation, so that the map follows it (and the TSDF is
  // fused again at the corrected poses, beside the end's texturing), then finishes.
  std::vector<planes::PatchEvent> finishStream() override;
  std::vector<planes::PatchSnapshot> snapshots(const std::vector<int>& ids) const override;

  DescribedPatch describe(const PatchJob& job) const override { return describe_.process(job); }
  std::optional<CommitMessage> commit(DescribedPatch described) override;

  void frameDone(const FusedFrame& fused) override;
  void committed(const CommitMessage& commit) override { sink_.writeCommit(commit); }
  void patchEvents(const std::vector<planes::PatchEvent>& events) override {
    sink_.writePatchEvents(events);
  }

  // How long the end of the stream waited for loop closure to catch up, seconds.
  double loopWaitS() const { return loop_wait_s_; }

 private:
  // Passes on the keyframes loop closure found revisiting a kept one's place: neither the
  // tracker nor the saved map keeps them.
  void forgetCoveredKeyframes();
  // On the committing thread, off the frame path, at most every freed_memory_return_.every_s.
  void returnFreedMemory();
  // On the frame path, while resident memory is above freed_memory_return_.above_mb and much
  // of it is freed memory: a burst of finalizations can fill the heap's free lists faster than
  // the commits come.
  void returnFreedMemoryAboveBudget();

  SourceStage& source_;
  TrackingStage& tracking_;
  IntegrationStage& integration_;
  PlaneStage& planes_;
  const DescribeStage& describe_;
  CommitStage& commit_;
  BitmapFiles& bitmaps_;
  StatsSink& sink_;
  loop::LoopCloser* loop_closer_;  // null without loop closure
  RunListener* listener_;          // may be null
  double loop_wait_s_ = 0.0;
  FreedMemoryReturn freed_memory_return_;
  // When memory was last returned after a commit, and above the budget (on the frame path).
  SteadyTime freed_memory_returned_at_ = std::chrono::steady_clock::now();
  SteadyTime over_budget_returned_at_ = freed_memory_returned_at_;
  MapSaver* map_saver_;        // null when the run saves no map
  CorrectedSurface* surface_;  // started once loop closure has finished; may be null
};

}  // namespace tessera::pipeline::internal
