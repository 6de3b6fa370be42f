#include "tessera/loop/loop_closer.h"

#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <exception>
#include <utility>

#include <omp.h>

#include <spdlog/spdlog.h>

namespace tessera::loop {

namespace {
constexpr int kWorkerNice = 5;
}  // namespace

LoopCloser::LoopCloser(const LoopConfig& config)
    : graph_(config), worker_([this] { work(); }) {}

LoopCloser::~LoopCloser() { finish(); }

void LoopCloser::add(std::shared_ptr<const fusion::KeyframeRecord> keyframe) {
  // Queued with its depth already thinned to what the graph keeps (80 x 60 of 640 x 480), so
  // that a worker far behind holds 19 KB per keyframe rather than the full 1.2 MB image.
  auto light = std::make_shared<fusion::KeyframeRecord>(*keyframe);
  light->depth_m = strideDepth(keyframe->depth_m, graph_.config().dense_stride);
  {
    const std::lock_guard<std::mutex> lock(mutex_);
    if (finishing_) return;
    queue_.push_back(std::move(light));
  }
  wake_.notify_one();
}

void LoopCloser::finish() {
  {
    const std::lock_guard<std::mutex> lock(mutex_);
    finishing_ = true;
  }
  wake_.notify_one();
  if (worker_.joinable()) worker_.join();
}

void LoopCloser::work() {
  // Below the frame path's priority (Linux nices threads one by one), above live texturing's
  // (pipeline.texture_nice_live, 10). At the lowest (19) it got about 1.5 % of a core
  // against the frame path's threads, while revisits take about 8 % (17 ms of CPU a keyframe,
  // 5 keyframes a second): on the loop ring its queue grew to 400 keyframes over five laps.
  setpriority(PRIO_PROCESS, static_cast<id_t>(syscall(SYS_gettid)), kWorkerNice);
  // One thread: Open3D's OpenMP loops (normals, ICP) would otherwise start a pool of threads
  // owned by this one, which end with it.
  omp_set_num_threads(1);
  for (;;) {
    std::shared_ptr<const fusion::KeyframeRecord> next;
    {
      std::unique_lock<std::mutex> lock(mutex_);
      wake_.wait(lock, [this] { return finishing_ || !queue_.empty(); });
      if (queue_.empty()) break;  // finishing, and nothing left
      next = std::move(queue_.front());
      queue_.pop_front();
    }
    try {
      graph_.add(*next, true);
      if (graph_.keyframes().back().covered) {
        const std::lock_guard<std::mutex> lock(published_mutex_);
        covered_ns_.push_back(next->timestamp_ns);
      }
      publish();
    } catch (const std::exception& e) {
      // A keyframe loop closure cannot use costs only its own loops, never the run.
      spdlog::warn("loop closure: keyframe at {} ns skipped: {}", next->timestamp_ns, e.what());
    }
  }
  try {
    graph_.finish();
    publish();
  } catch (const std::exception& e) {
    spdlog::warn("loop closure: the final optimisation failed: {}", e.what());
  }
}

std::size_t LoopCloser::waiting() const {
  const std::lock_guard<std::mutex> lock(mutex_);
  return queue_.size();
}

std::vector<std::int64_t> LoopCloser::takeCovered() {
  const std::lock_guard<std::mutex> lock(published_mutex_);
  return std::exchange(covered_ns_, {});
}

std::shared_ptr<const MapCorrection> LoopCloser::correction() const {
  const std::lock_guard<std::mutex> lock(published_mutex_);
  return published_;
}

void LoopCloser::publish() {
  const std::size_t generation = graph_.stats().optimisations;
  if (generation == 0) return;
  {
    const std::lock_guard<std::mutex> lock(published_mutex_);
    if (published_ && published_->generation == generation) return;
  }
  auto correction = std::make_shared<const MapCorrection>(graph_.correction());
  const std::lock_guard<std::mutex> lock(published_mutex_);
  published_ = std::move(correction);
}

}  // namespace tessera::loop
