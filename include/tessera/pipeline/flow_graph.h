#pragma once
// The one place that knows the topology, as a tbb::flow::graph inside a task_arena of the
// requested concurrency:
//
//   source -> limiter -> tracking -> integration -> loops -> planes -------> report
//                ^                                    | finalized patches       ^
//                |                                    v                         |
//                |                        describe (many at once)               |
//                |                                    v                         |
//                |                       commit (serial, in finalization order) -+
//                +------- a frame reported frees its place (unless too many ----+
//                         patches wait for their commits: then a commit does)
//
// Every serial stage takes its messages in order: frames in stream order, patches in
// finalization order (sequencer nodes). Keyframes travel with their frame to the loops node,
// which hands them to loop closure (its own thread) and gives each frame the newest map
// correction for the plane stage. The report node is the only one that writes the run's
// figures; commit records reach it on an edge. The graph calls the stages through the
// narrow interfaces below, so that it can be tested with fakes.
#include <cstddef>
#include <optional>
#include <vector>

#include "tessera/pipeline/stages.h"
#include "tessera/pipeline/texture_db_stages.h"

namespace tessera::pipeline {

// The frame path: serial stages called one frame at a time, in stream order.
class FramePath {
 public:
  virtual ~FramePath() = default;
  virtual std::optional<core::Frame> next() = 0;  // nothing: the end of the stream
  virtual TrackedFrame track(core::Frame frame) = 0;
  virtual FusedFrame integrate(TrackedFrame tracked) = 0;
  // Hands the frame's new keyframes to loop closure and gives it the newest map correction
  // (FusedFrame::loop_correction); without loop closure, nothing.
  virtual FusedFrame closeLoops(FusedFrame fused) = 0;
  // Also names the patches the frame finalized (finalized_patches) and what else changed
  // (patch_events).
  virtual FusedFrame findPlanes(FusedFrame fused) = 0;
  // End of the stream: finalizes what is left and says what changed.
  virtual std::vector<planes::PatchEvent> finishStream() = 0;
  // After finishStream: a copy of each patch `ids` names, for texturing. The graph takes them a
  // few at a time, so that the backlog's bound holds at the end too.
  virtual std::vector<planes::PatchSnapshot> snapshots(const std::vector<int>& ids) const = 0;
};

// The patch path: each finalized patch described (many at once), then committed one at a time
// in finalization order.
class PatchPath {
 public:
  virtual ~PatchPath() = default;
  virtual DescribedPatch describe(const PatchJob& job) const = 0;  // thread-safe
  // What the report is told of the commit; nothing for a retirement.
  virtual std::optional<CommitMessage> commit(DescribedPatch described) = 0;
};

// Where the run's figures go; called from one node at a time: frames in stream order,
// commits in finalization order.
class RunReport {
 public:
  virtual ~RunReport() = default;
  virtual void frameDone(const FusedFrame& fused) = 0;
  virtual void committed(const CommitMessage& commit) = 0;
  // At the end of the stream (the graph waits), what finishing the patches changed.
  virtual void patchEvents(const std::vector<planes::PatchEvent>& events) = 0;
};

struct GraphOptions {
  int threads = 0;               // 0: hardware threads
  int max_frames_in_flight = 4;  // replay back-pressure (limiter_node)
  // How far the nice value of the threads that describe and commit patches is raised above
  // the caller's (0: not at all): with the cores short, the frame path goes first and
  // texturing waits.
  int texture_nice = 0;
  // Finalized patches (and retirements) waiting to be described and committed, at most; at
  // the bound the frame path waits (a live device drops frames). The frames already in
  // flight may still finalize a few more.
  int max_patches_waiting = 4;
  // > 0: the bound is instead the waiting patches' colour samples, in bytes (live sources).
  std::size_t max_patch_bytes_waiting = 0;
  // Threads that describe finalized patches; 0: half of `threads`, at least 1. The frame path
  // keeps the other half busy, and more describers than free cores only take turns with it.
  int describing_threads = 0;
};

// Runs the stages over the whole stream, then finishes the patches (end of stream) and waits
// for their commits. Blocks until done; returns the frames reported.
std::size_t runGraph(FramePath& frames, PatchPath& patches, RunReport& report,
                     const GraphOptions& options);

// Hardware threads, at least 1.
int defaultThreadCount();

}  // namespace tessera::pipeline
