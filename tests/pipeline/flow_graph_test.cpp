// The flow graph alone, with fake stages that sleep seeded random times: every serial stage sees
// the frames in stream order, patches are committed in the order they were finalized (the
// end-of-stream patches last), each batch's commits all reach the report, the report is never
// called by two threads at once, and no more frames are in flight than the limiter allows;
// texturing runs at a lower priority than the frame path, the frame path waits while too many
// patches (or, live, too many bytes of their colour samples) wait for their textures, and a failure
// to describe a patch ends the run with its error; for 1, 2 and 4 threads. At the end of the
// stream every thread describes, and the patches left are handed over as commits free places.
#include "tessera/pipeline/flow_graph.h"

#include <atomic>
#include <chrono>
#include <map>
#include <mutex>
#include <random>
#include <thread>

#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <gtest/gtest.h>

namespace tessera::pipeline {
namespace {

// The calling thread's own nice value.
int threadNice() { return ::getpriority(PRIO_PROCESS, static_cast<id_t>(::syscall(SYS_gettid))); }

// Sleeps up to `max_us`, drawn from `random`.
void nap(std::mt19937& random, int max_us) {
  std::this_thread::sleep_for(
      std::chrono::microseconds(std::uniform_int_distribution<int>(0, max_us)(random)));
}

constexpr std::size_t kSamplesPerPatch = 1000;
constexpr std::size_t kPatchBytes = kSamplesPerPatch * sizeof(planes::ColourSample);

planes::PatchSnapshot patch(int id) {
  planes::PatchSnapshot snapshot;
  snapshot.id = id;
  snapshot.version = 1;
  snapshot.samples.resize(kSamplesPerPatch);
  return snapshot;
}

constexpr int kStreamFrames = 60;
constexpr int kInFlight = 3;

// Frames 0..kStreamFrames-1. Every third frame finalizes one or two patches; every tenth retires
// the oldest patch not yet retired. The end of the stream finalizes three more and retires one.
class FakeFrames : public FramePath {
 public:
  std::optional<core::Frame> next() override {
    nap(source_random_, 300);
    if (read_ == kStreamFrames) {
      stream_read = true;
      return std::nullopt;
    }
    core::Frame frame;
    frame.index = static_cast<std::uint64_t>(read_++);
    frame.timestamp_ns = static_cast<std::int64_t>(frame.index) * 33'000'000;
    max_in_flight = std::max(max_in_flight.load(), ++in_flight);
    return frame;
  }
  TrackedFrame track(core::Frame frame) override {
    nap(track_random_, 800);
    track_nice = threadNice();
    out_of_order += frame.index != tracked_++ ? 1 : 0;
    TrackedFrame tracked;
    tracked.frame = std::move(frame);
    tracked.T_W_C = core::Isometry::Identity();
    return tracked;
  }
  FusedFrame integrate(TrackedFrame tracked) override {
    nap(integrate_random_, 800);
    out_of_order += tracked.frame.index != integrated_++ ? 1 : 0;
    FusedFrame fused;
    fused.frame = std::move(tracked.frame);
    fused.integrated = true;
    return fused;
  }
  FusedFrame closeLoops(FusedFrame fused) override {
    out_of_order += fused.frame.index != looped_++ ? 1 : 0;
    return fused;
  }
  FusedFrame findPlanes(FusedFrame fused) override {
    nap(planes_random_, 800);
    const std::uint64_t index = fused.frame.index;
    out_of_order += index != planned_++ ? 1 : 0;
    if (index % 10 == 9 && retired_ < next_id_) {
      fused.patch_events.push_back({planes::PatchEvent::Kind::kRetired, retired_, 1});
      finalization_order.push_back(-retired_++);
    }
    if (index % 3 == 0) {
      for (std::uint64_t i = 0; i < 1 + index % 2; ++i) {
        fused.finalized_patches.push_back(patch(next_id_));
        finalization_order.push_back(next_id_);
        batch_of_patch[next_id_++] = index;
      }
    }
    if (commits_done != nullptr) {
      const int waiting = static_cast<int>(finalization_order.size()) - *commits_done;
      max_waiting = std::max(max_waiting, waiting);
    }
    return fused;
  }
  std::vector<planes::PatchEvent> finishStream() override {
    stream_finished = true;
    std::vector<planes::PatchEvent> events{{planes::PatchEvent::Kind::kRetired, retired_, 1}};
    finalization_order.push_back(-retired_++);
    for (int i = 0; i < kFinalizedAtTheEnd; ++i) {
      events.push_back({planes::PatchEvent::Kind::kFinalized, next_id_, 1});
      finalization_order.push_back(next_id_);
      batch_of_patch[next_id_++] = kStreamFrames;  // the end's batch: after the last frame
    }
    return events;
  }
  std::vector<planes::PatchSnapshot> snapshots(const std::vector<int>& ids) const override {
    end_parts.push_back(ids.size());
    std::vector<planes::PatchSnapshot> out;
    for (const int id : ids) out.push_back(patch(id));
    return out;
  }
  static constexpr int kFinalizedAtTheEnd = 10;
  mutable std::vector<std::size_t> end_parts;  // how many patches each snapshots() call copied

  std::atomic<int> in_flight{0}, max_in_flight{0}, out_of_order{0}, track_nice{-100};
  std::atomic<bool> stream_read{false};  // the source said the stream ended
  std::atomic<bool> stream_finished{false};  // finishStream was called
  std::vector<int> finalization_order;  // patch ids; a retirement as -id
  // Patch jobs (finalized and retired) queued and not yet committed, at most, when
  // `commits_done` counts the commits.
  const std::atomic<int>* commits_done = nullptr;
  int max_waiting = 0;
  static constexpr int kMostJobsPerFrame = 3;  // two finalized, one retired
  std::map<int, std::uint64_t> batch_of_patch;

 private:
  std::mt19937 source_random_{1}, track_random_{2}, integrate_random_{3}, planes_random_{4};
  int read_ = 0;
  std::uint64_t tracked_ = 0, integrated_ = 0, looped_ = 0, planned_ = 0;
  int next_id_ = 1, retired_ = 1;
};

class FakePatches : public PatchPath {
 public:
  DescribedPatch describe(const PatchJob& job) const override {
    const int now = ++describing;
    std::atomic<int>& at_most =
        end_reached != nullptr && *end_reached ? max_describing_at_end : max_describing;
    for (int most = at_most; now > most && !at_most.compare_exchange_weak(most, now);) {
    }
    std::mt19937 random(static_cast<unsigned>(job.sequence) + 7);
    nap(random, describe_max_us);  // many at once, finishing out of order
    // At the end, until two were seen describing at once, waits (a few seconds at most) for a
    // second describer, so that whether the end describes on two threads does not depend on
    // timing.
    for (int ms = 0; pair_at_end && end_reached != nullptr && *end_reached &&
                     max_describing_at_end < 2 && ms < 5000;
         ++ms) {
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
      const int both = describing;
      for (int most = max_describing_at_end;
           both > most && !max_describing_at_end.compare_exchange_weak(most, both);) {
      }
    }
    --describing;
    while (hold_until != nullptr && !*hold_until) {
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    describe_nice = threadNice();
    if (job.patch.id == fail_on_patch) throw std::runtime_error("describe failed");
    DescribedPatch described;
    described.sequence = job.sequence;
    described.retired = job.retired;
    described.batch = job.batch;
    described.batch_size = job.batch_size;
    described.frame_index = job.frame_index;
    if (!job.retired) {
      described.bitmap.emplace();
      described.bitmap->id = job.patch.id;
    }
    return described;
  }
  std::optional<CommitMessage> commit(DescribedPatch described) override {
    commit_nice = threadNice();
    out_of_order += described.sequence != committed_++ ? 1 : 0;
    ++commits_done;
    if (described.retired) {
      commit_order.push_back(-*described.retired);
      return std::nullopt;
    }
    commit_order.push_back(described.bitmap->id);
    CommitMessage message;
    message.record.patch_id = described.bitmap->id;
    message.batch = described.batchInfo();
    return message;
  }

  std::atomic<int> out_of_order{0};
  std::vector<int> commit_order;
  mutable std::atomic<int> describe_nice{-100};
  // Patches being described at once: now, at most during the stream, at most at its end
  // (once `end_reached` is set).
  mutable std::atomic<int> describing{0}, max_describing{0}, max_describing_at_end{0};
  const std::atomic<bool>* end_reached = nullptr;
  bool pair_at_end = false;  // at the end, wait for a second describer
  std::atomic<int> commit_nice{-100}, commits_done{0};
  int fail_on_patch = -1;
  int describe_max_us = 3000;
  const std::atomic<bool>* hold_until = nullptr;  // describing waits until it is set

 private:
  std::size_t committed_ = 0;
};

class FakeReport : public RunReport {
 public:
  explicit FakeReport(FakeFrames& frames) : frames_(frames) {}

  void frameDone(const FusedFrame& fused) override {
    Alone alone(*this);
    --frames_.in_flight;
    out_of_order += fused.frame.index != reported_++ ? 1 : 0;
  }
  void committed(const CommitMessage& commit) override {
    Alone alone(*this);
    reported_commits.push_back(commit.record.patch_id);
    Batch& batch = batches[commit.batch.index];
    batch.size = commit.batch.size;
    batch.frame_index = commit.batch.frame_index;
    batch.patches.push_back(commit.record.patch_id);
  }
  void patchEvents(const std::vector<planes::PatchEvent>& events) override {
    Alone alone(*this);
    end_events += events.size();
  }

  struct Batch {
    std::size_t size = 0;
    std::uint64_t frame_index = 0;
    std::vector<int> patches;
  };
  std::atomic<int> out_of_order{0}, overlaps{0};
  std::vector<int> reported_commits;
  std::map<std::size_t, Batch> batches;
  std::size_t end_events = 0;

 private:
  // Counts a call that began while another was still running.
  struct Alone {
    explicit Alone(FakeReport& report) : report_(report) {
      if (report_.busy_.exchange(true)) ++report_.overlaps;
    }
    ~Alone() { report_.busy_ = false; }
    FakeReport& report_;
  };
  FakeFrames& frames_;
  std::uint64_t reported_ = 0;
  std::atomic<bool> busy_{false};
};

class FlowGraphTest : public ::testing::TestWithParam<int> {};

TEST_P(FlowGraphTest, KeepsOrderBatchesAndBackPressureAndFlushesAtTheEnd) {
  FakeFrames frames;
  FakePatches patches;
  patches.end_reached = &frames.stream_finished;
  FakeReport report(frames);
  const int nice = threadNice();
  const std::size_t reported = runGraph(frames, patches, report, {GetParam(), kInFlight, 5});

  EXPECT_EQ(reported, static_cast<std::size_t>(kStreamFrames));
  EXPECT_EQ(frames.out_of_order, 0) << "a serial frame stage saw frames out of order";
  EXPECT_EQ(report.out_of_order, 0) << "the report saw frames out of order";
  EXPECT_EQ(patches.out_of_order, 0) << "commits out of finalization order";
  EXPECT_EQ(report.overlaps, 0) << "two threads in the report at once";
  // Half the threads describe (at least one); the frame path keeps the other half.
  EXPECT_LE(patches.max_describing, std::max(1, GetParam() / 2));
  EXPECT_LE(patches.max_describing_at_end, GetParam());
  // The source may hold one frame it read and the limiter has not admitted yet.
  EXPECT_LE(frames.max_in_flight, kInFlight + 1);
  EXPECT_EQ(frames.in_flight, 0);

  // Every patch and retirement, end of stream included, committed in finalization order.
  EXPECT_EQ(patches.commit_order, frames.finalization_order);
  std::vector<int> finalized;
  for (int id : frames.finalization_order) {
    if (id > 0) finalized.push_back(id);
  }
  EXPECT_EQ(report.reported_commits, finalized);
  EXPECT_EQ(report.end_events, 1u + FakeFrames::kFinalizedAtTheEnd);

  // Each batch: the patches one frame finalized, all reported, named with that frame.
  std::size_t patches_in_batches = 0;
  for (const auto& [index, batch] : report.batches) {
    EXPECT_EQ(batch.patches.size(), batch.size) << "batch " << index;
    for (int id : batch.patches) EXPECT_EQ(frames.batch_of_patch.at(id), batch.frame_index);
    patches_in_batches += batch.patches.size();
  }
  EXPECT_EQ(patches_in_batches, finalized.size());
  ASSERT_FALSE(report.batches.empty());
  EXPECT_EQ(report.batches.rbegin()->second.frame_index, static_cast<std::uint64_t>(kStreamFrames));
  EXPECT_EQ(report.batches.rbegin()->second.size,
            static_cast<std::size_t>(FakeFrames::kFinalizedAtTheEnd));
  // The end's patches are copied (colour samples and all) as the backlog's bound (4) allows:
  // four, then one as each is committed.
  EXPECT_EQ(frames.end_parts, (std::vector<std::size_t>{4, 1, 1, 1, 1, 1, 1}));

  // Texturing runs at a lower priority than the frame path.
  EXPECT_EQ(frames.track_nice, nice);
  EXPECT_EQ(patches.describe_nice, std::min(19, nice + 5));
  EXPECT_EQ(patches.commit_nice, std::min(19, nice + 5));
}

TEST(FlowGraph, DescribesOnAsManyThreadsAsAskedFor) {
  FakeFrames frames;
  FakePatches patches;
  patches.describe_max_us = 20'000;  // long enough for the patches to queue
  FakeReport report(frames);
  GraphOptions options{2, kInFlight, 0};
  options.describing_threads = 3;
  EXPECT_EQ(runGraph(frames, patches, report, options), static_cast<std::size_t>(kStreamFrames));
  EXPECT_EQ(patches.commit_order, frames.finalization_order);
  EXPECT_LE(patches.max_describing, 3);
  EXPECT_GE(patches.max_describing, 2) << "the queued patches were described one at a time";
}

// Once the frames are over, the frame path's cores describe too.
TEST(FlowGraph, EveryThreadDescribesAtTheEndOfTheStream) {
  FakeFrames frames;
  FakePatches patches;
  patches.end_reached = &frames.stream_finished;
  patches.pair_at_end = true;
  FakeReport report(frames);
  EXPECT_EQ(runGraph(frames, patches, report, {2, kInFlight, 0}),
            static_cast<std::size_t>(kStreamFrames));
  EXPECT_EQ(patches.commit_order, frames.finalization_order);
  EXPECT_EQ(patches.max_describing, 1);
  EXPECT_EQ(patches.max_describing_at_end, 2);
}

TEST(FlowGraph, AFailureToDescribeAPatchEndsTheRunWithItsError) {
  FakeFrames frames;
  FakePatches patches;
  patches.fail_on_patch = 2;
  FakeReport report(frames);
  EXPECT_THROW(runGraph(frames, patches, report, {2, kInFlight, 5}), std::runtime_error);
}

TEST_P(FlowGraphTest, HoldsTheFramePathBackWhileTooManyPatchesWaitForTextures) {
  // Describing is slow, so texturing falls behind the frames. Bounded, the frame path waits,
  // and only the frames already past the limiter add to the bound. Unbounded (and describing
  // held until the whole stream is read, so that timing cannot decide it), every patch job of
  // the stream waits at once.
  auto run = [](int threads, int bound, std::size_t bound_bytes = 0) {
    FakeFrames frames;
    FakePatches patches;
    patches.describe_max_us = 20'000;
    const bool unbounded = bound_bytes > 0 ? bound_bytes > 100 * kPatchBytes : bound > 100;
    if (unbounded) patches.hold_until = &frames.stream_read;
    frames.commits_done = &patches.commits_done;
    FakeReport report(frames);
    EXPECT_EQ(runGraph(frames, patches, report, {threads, kInFlight, 0, bound, bound_bytes}),
              static_cast<std::size_t>(kStreamFrames));
    EXPECT_EQ(patches.commit_order, frames.finalization_order);
    EXPECT_EQ(frames.in_flight, 0);
    return frames.max_waiting;
  };
  const int bound = 1;
  const int allowance = bound + kInFlight * FakeFrames::kMostJobsPerFrame;
  EXPECT_LE(run(GetParam(), bound), allowance);
  EXPECT_GT(run(GetParam(), 1000), allowance) << "the test's stream does not overload texturing";

  // Live: the bound is the waiting patches' samples, whatever their count. Two patches' worth
  // holds the backlog like a bound of two (retirements, without samples, may add one);
  // a thousand patches' worth does not hold it, though the count's bound is 1.
  EXPECT_LE(run(GetParam(), 1, 2 * kPatchBytes), allowance + 2);
  EXPECT_GT(run(GetParam(), 1, 1000 * kPatchBytes), allowance);
}

INSTANTIATE_TEST_SUITE_P(Threads, FlowGraphTest, ::testing::Values(1, 2, 4),
                         [](const auto& test) { return std::to_string(test.param) + "Threads"; });

}  // namespace
}  // namespace tessera::pipeline
