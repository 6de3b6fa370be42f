#include "tessera/pipeline/flow_graph.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <thread>
#include <tuple>

#include <oneapi/tbb/flow_graph.h>
#include <oneapi/tbb/task_arena.h>

#include "internal/background_workers.h"

namespace tessera::pipeline {

namespace flow = oneapi::tbb::flow;

namespace {

// A message with its frame's place in the stream.
template <class T>
struct Numbered {
  std::uint64_t number = 0;
  T item;
};

// Patch jobs and described patches travel the graph by pointer: the graph copies its messages
// (into tasks, buffers and the workers' jobs), and a described patch holds its bitmap, often
// tens of MB.
using JobMessage = std::shared_ptr<const PatchJob>;
using DescribedMessage = std::shared_ptr<DescribedPatch>;

// Numbers the patches the plane stage finalizes (and those it retires) in the order they
// happened, and groups each frame's finalized patches into one batch.
class PatchJobs {
 public:
  std::vector<JobMessage> finalized(std::vector<planes::PatchSnapshot>& patches,
                                    std::uint64_t frame_index) {
    openBatch(patches.size(), frame_index);
    return inOpenBatch(patches);
  }
  // A batch of `size` patches finalized now by frame `frame_index`, whose copies may come in
  // parts (inOpenBatch).
  void openBatch(std::size_t size, std::uint64_t frame_index) {
    batch_ = {size > 0 ? next_batch_++ : next_batch_, size, frame_index,
              std::chrono::steady_clock::now()};
  }
  std::vector<JobMessage> inOpenBatch(std::vector<planes::PatchSnapshot>& patches) {
    std::vector<JobMessage> jobs;
    for (planes::PatchSnapshot& patch : patches) {
      jobs.push_back(std::make_shared<const PatchJob>(PatchJob{next_sequence_++,
                                                               batch_.index,
                                                               batch_.size,
                                                               batch_.frame_index,
                                                               std::move(patch),
                                                               batch_.finalized_at,
                                                               {}}));
    }
    patches.clear();
    return jobs;
  }

  // Patches merged into others leave the database in the same order.
  std::vector<JobMessage> retired(const std::vector<planes::PatchEvent>& events) {
    std::vector<JobMessage> jobs;
    for (const planes::PatchEvent& event : events) {
      if (event.kind != planes::PatchEvent::Kind::kRetired) continue;
      PatchJob job;
      job.sequence = next_sequence_++;
      job.retired = event.id;
      jobs.push_back(std::make_shared<const PatchJob>(std::move(job)));
    }
    return jobs;
  }

 private:
  struct OpenBatch {
    std::size_t index = 0, size = 0;
    std::uint64_t frame_index = 0;
    std::chrono::steady_clock::time_point finalized_at;
  };
  std::size_t next_sequence_ = 0, next_batch_ = 0;
  OpenBatch batch_;
};

// Holds the frame path back while too many patch jobs wait to be described and committed: a
// frame reported while the bound is reached keeps its place in the limiter until commits free
// one. A replay's source then waits; a live device drops frames instead. Without it texturing
// that falls behind queues patches, colour samples and all, without end. The bound counts the
// jobs, or (live) the bytes of their colour samples.
class PatchBacklog {
 public:
  PatchBacklog(std::size_t max_jobs, std::size_t max_bytes)
      : max_jobs_(max_jobs), max_bytes_(max_bytes) {}

  // The plane stage (or the end of the stream) queued `jobs` more, in their sequence order.
  void queued(const std::vector<JobMessage>& jobs) {
    const std::lock_guard lock(mutex_);
    for (const JobMessage& job : jobs) {
      const std::size_t bytes = planes::sampleCount(job->patch) * sizeof(planes::ColourSample);
      waiting_.push_back(bytes);
      waiting_bytes_ += bytes;
    }
  }
  // The report node's calls (serial): how many limiter places to free now.
  std::size_t frameReported() {
    const std::lock_guard lock(mutex_);
    if (!full()) return 1;
    ++withheld_;
    return 0;
  }
  // Jobs are committed in their sequence order: the oldest waiting one is done.
  std::size_t jobDone() {
    const std::lock_guard lock(mutex_);
    if (!waiting_.empty()) {
      waiting_bytes_ -= waiting_.front();
      waiting_.pop_front();
    }
    std::size_t freed = 0;
    while (withheld_ > 0 && !full()) {
      --withheld_;
      ++freed;
    }
    return freed;
  }

 private:
  bool full() const {
    return max_bytes_ > 0 ? waiting_bytes_ >= max_bytes_ : waiting_.size() >= max_jobs_;
  }

  const std::size_t max_jobs_, max_bytes_;
  std::mutex mutex_;                 // the plane stage queues, the report node counts
  std::deque<std::size_t> waiting_;  // each waiting job's sample bytes, oldest first
  std::size_t waiting_bytes_ = 0, withheld_ = 0;
};

// The patches still live at the end of the stream, handed to texturing a few at a time: at
// first `in_flight`, then one more as each is committed, so that the backlog's bound holds
// at the end too (a long walk's process peak was once these jobs, when each held a copy of
// its patch's colour samples) and no describing thread idles while another finishes a large
// patch. Called from the end of the stream and from the report node.
class EndOfStreamFeed {
 public:
  using HandOver = std::function<void(std::vector<int>)>;

  void start(std::vector<int> ids, std::size_t in_flight, HandOver hand_over) {
    const std::lock_guard lock(mutex_);
    ids_ = std::move(ids);
    in_flight_ = std::max<std::size_t>(1, in_flight);
    hand_over_ = std::move(hand_over);
    handLocked(in_flight_);
  }
  // A patch was committed: the next takes its place.
  void oneCommitted() {
    const std::lock_guard lock(mutex_);
    handLocked(1);
  }
  // The graph went idle with patches left (a job that ended without a commit frees no
  // place): the next few. False when none was left.
  bool handMore() {
    const std::lock_guard lock(mutex_);
    return handLocked(in_flight_);
  }

 private:
  bool handLocked(std::size_t count) {
    if (next_ >= ids_.size() || !hand_over_) return false;
    const std::size_t end = std::min(ids_.size(), next_ + count);
    std::vector<int> some(ids_.begin() + static_cast<std::ptrdiff_t>(next_),
                          ids_.begin() + static_cast<std::ptrdiff_t>(end));
    next_ = end;
    hand_over_(std::move(some));
    return true;
  }

  std::mutex mutex_;
  std::vector<int> ids_;
  std::size_t next_ = 0, in_flight_ = 1;
  HandOver hand_over_;
};

// Tells the graph that an async node's job is done (however it ended), so that
// wait_for_all does not wait for it any more.
template <class Gateway>
struct ReleaseWait {
  Gateway& gateway;
  ~ReleaseWait() { gateway.release_wait(); }
};
template <class Gateway>
ReleaseWait(Gateway&) -> ReleaseWait<Gateway>;

}  // namespace

int defaultThreadCount() {
  const unsigned hardware = std::thread::hardware_concurrency();
  return hardware == 0 ? 1 : static_cast<int>(hardware);
}

std::size_t runGraph(FramePath& frames, PatchPath& patches, RunReport& report,
                     const GraphOptions& options) {
  const int threads = options.threads > 0 ? options.threads : defaultThreadCount();
  std::size_t frames_reported = 0;  // frames of the stream, interruption markers aside
  oneapi::tbb::task_arena arena(threads);
  // Declared before the graph that hands them work, so that they outlive it.
  const int describing =
      options.describing_threads > 0 ? options.describing_threads : std::max(1, threads / 2);
  internal::BackgroundWorkers describers(describing, options.texture_nice);
  internal::BackgroundWorkers committer(1, options.texture_nice);
  arena.execute([&] {
    flow::graph graph;

    // Each frame gets a number at the source, and a sequencer in front of each serial stage
    // hands it the frames in that order: a serial function_node alone does not keep the order
    // its messages came in, and a plane stage that saw two frames swapped found other patches.
    std::uint64_t next_frame = 0;
    flow::input_node<Numbered<core::Frame>> source_node(
        graph, [&](oneapi::tbb::flow_control& control) {
          std::optional<core::Frame> frame = frames.next();
          if (!frame) {
            control.stop();
            return Numbered<core::Frame>{};
          }
          return Numbered<core::Frame>{next_frame++, std::move(*frame)};
        });
    // Replay: never drop a frame; hold the source back instead.
    flow::limiter_node<Numbered<core::Frame>> limiter(
        graph, static_cast<std::size_t>(options.max_frames_in_flight));
    // Serial stages in a row: while frame N is integrated, frame N+1 is tracked and frame N-1
    // goes through plane detection.
    auto numbered = [](const auto& message) { return message.number; };
    flow::sequencer_node<Numbered<core::Frame>> to_tracking(graph, numbered);
    flow::function_node<Numbered<core::Frame>, Numbered<TrackedFrame>> tracking_node(
        graph, flow::serial, [&](Numbered<core::Frame> frame) {
          return Numbered<TrackedFrame>{frame.number, frames.track(std::move(frame.item))};
        });
    flow::sequencer_node<Numbered<TrackedFrame>> to_integration(graph, numbered);
    flow::function_node<Numbered<TrackedFrame>, Numbered<FusedFrame>> integration_node(
        graph, flow::serial, [&](Numbered<TrackedFrame> tracked) {
          return Numbered<FusedFrame>{tracked.number, frames.integrate(std::move(tracked.item))};
        });
    flow::sequencer_node<Numbered<FusedFrame>> to_loops(graph, numbered);
    flow::function_node<Numbered<FusedFrame>, Numbered<FusedFrame>> loops_node(
        graph, flow::serial, [&](Numbered<FusedFrame> fused) {
          return Numbered<FusedFrame>{fused.number, frames.closeLoops(std::move(fused.item))};
        });
    flow::sequencer_node<Numbered<FusedFrame>> to_planes(graph, numbered);
    // The plane stage sends the frame on to the report and each patch it finalized (or
    // retired) to the patch path, numbered in the order it happened.
    PatchJobs jobs;
    EndOfStreamFeed end_feed;  // idle until the end of the stream
    PatchBacklog backlog(static_cast<std::size_t>(std::max(1, options.max_patches_waiting)),
                         options.max_patch_bytes_waiting);
    auto queue = [&backlog](std::vector<JobMessage> batch, auto& to) {
      backlog.queued(batch);
      for (JobMessage& job : batch) to.try_put(std::move(job));
    };
    using PlanesNode = flow::multifunction_node<Numbered<FusedFrame>,
                                                std::tuple<Numbered<FusedFrame>, JobMessage>>;
    PlanesNode planes_node(
        graph, flow::serial, [&](Numbered<FusedFrame> fused, PlanesNode::output_ports_type& out) {
          fused.item = frames.findPlanes(std::move(fused.item));
          queue(jobs.retired(fused.item.patch_events), std::get<1>(out));
          queue(jobs.finalized(fused.item.finalized_patches, fused.item.frame.index),
                std::get<1>(out));
          std::get<0>(out).try_put(std::move(fused));
        });
    // Bitmaps are built and described independently: as many at once as there are describing
    // threads, off the frame path. They are committed one at a time, in finalization order. Both
    // run on threads of their own at a lower priority (internal/background_workers.h), handed over
    // by async nodes.
    using DescribeNode = flow::async_node<JobMessage, DescribedMessage>;
    DescribeNode describe_node(
        graph, flow::unlimited, [&](const JobMessage& job, DescribeNode::gateway_type& gateway) {
          gateway.reserve_wait();
          describers.submit([&patches, &gateway, job] {
            const ReleaseWait release{gateway};
            gateway.try_put(std::make_shared<DescribedPatch>(patches.describe(*job)));
          });
        });
    flow::sequencer_node<DescribedMessage> in_order(
        graph, [](const DescribedMessage& described) { return described->sequence; });
    // Every commit reaches the report, a retirement's (nothing to say) too, so that the
    // backlog counts it done.
    using Committed = std::optional<CommitMessage>;
    using CommitNode = flow::async_node<DescribedMessage, Committed>;
    CommitNode commit_node(
        graph, flow::serial,
        [&](const DescribedMessage& described, CommitNode::gateway_type& gateway) {
          gateway.reserve_wait();
          committer.submit([&patches, &gateway, described] {
            const ReleaseWait release{gateway};
            gateway.try_put(patches.commit(std::move(*described)));
          });
        });
    // Frames (in stream order) and commits (in finalization order) meet at the one node that
    // writes the report; a reported frame lets the source read another, unless the backlog
    // withholds its place.
    flow::sequencer_node<Numbered<FusedFrame>> to_report(graph, numbered);
    using ReportInput = flow::indexer_node<Numbered<FusedFrame>, Committed>;
    ReportInput report_input(graph);
    using ReportNode =
        flow::multifunction_node<ReportInput::output_type, std::tuple<flow::continue_msg>>;
    ReportNode report_node(
        graph, flow::serial,
        [&](const ReportInput::output_type& message, ReportNode::output_ports_type& out) {
          std::size_t places = 0;
          if (message.tag() == 1) {
            if (const Committed& committed = flow::cast_to<Committed>(message)) {
              report.committed(*committed);
              end_feed.oneCommitted();
            }
            places = backlog.jobDone();
          } else {
            const FusedFrame& fused = flow::cast_to<Numbered<FusedFrame>>(message).item;
            report.frameDone(fused);
            if (!fused.frame.source_interrupted) ++frames_reported;
            places = backlog.frameReported();
          }
          for (; places > 0; --places) std::get<0>(out).try_put(flow::continue_msg{});
        });

    flow::make_edge(source_node, limiter);
    flow::make_edge(limiter, to_tracking);
    flow::make_edge(to_tracking, tracking_node);
    flow::make_edge(tracking_node, to_integration);
    flow::make_edge(to_integration, integration_node);
    flow::make_edge(integration_node, to_loops);
    flow::make_edge(to_loops, loops_node);
    flow::make_edge(loops_node, to_planes);
    flow::make_edge(to_planes, planes_node);
    flow::make_edge(flow::output_port<0>(planes_node), to_report);
    flow::make_edge(to_report, flow::input_port<0>(report_input));
    flow::make_edge(flow::output_port<1>(planes_node), describe_node);
    flow::make_edge(describe_node, in_order);
    flow::make_edge(in_order, commit_node);
    flow::make_edge(commit_node, flow::input_port<1>(report_input));
    flow::make_edge(report_input, report_node);
    flow::make_edge(flow::output_port<0>(report_node), limiter.decrementer());

    source_node.activate();
    graph.wait_for_all();

    // End of stream: the patches still live are finalized and textured like the others, as
    // the backlog allows (EndOfStreamFeed). No frame needs a core any more, so every core
    // describes (a loop closure near the end leaves most patches to texture here); the
    // commit order, and so the result, stays the same.
    const std::vector<planes::PatchEvent> events = frames.finishStream();
    describers.growTo(threads);
    report.patchEvents(events);
    queue(jobs.retired(events), describe_node);
    const std::vector<int> ids = planes::finalizedIds(events);
    jobs.openBatch(ids.size(), frames_reported);
    end_feed.start(ids, static_cast<std::size_t>(std::max(1, options.max_patches_waiting)),
                   [&](std::vector<int> some) {
                     std::vector<planes::PatchSnapshot> finalized = frames.snapshots(some);
                     queue(jobs.inOpenBatch(finalized), describe_node);
                   });
    // A job that failed leaves the commits behind it waiting: the run ends with its error.
    do {
      graph.wait_for_all();  // the retirements too, when nothing was finalized
    } while (!describers.failed() && !committer.failed() && end_feed.handMore());
  });
  describers.rethrowFirst();
  committer.rethrowFirst();
  return frames_reported;
}

}  // namespace tessera::pipeline
