#pragma once
// Runs loop closure (loop_graph.h) on its own thread, off the frame path: the tracking stage
// hands over keyframes without waiting, and the run reads the corrected trajectory at the end.
//
// Thread-safety: add() from one thread (the tracking stage); correction() from any thread at
// any time; finish() and graph() after the stream has ended.
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <memory>
#include <mutex>
#include <thread>
#include <vector>

#include "tessera/loop/loop_graph.h"

namespace tessera::loop {

class LoopCloser {
 public:
  explicit LoopCloser(const LoopConfig& config);
  ~LoopCloser();
  LoopCloser(const LoopCloser&) = delete;
  LoopCloser& operator=(const LoopCloser&) = delete;

  void add(std::shared_ptr<const fusion::KeyframeRecord> keyframe);

  // Waits until every keyframe handed over is processed and the graph is optimised. The
  // readers below are valid after it.
  void finish();

  const LoopGraph& graph() const { return graph_; }

  // The correction after the newest optimisation, or nothing before the first. The map
  // (PlaneStage) follows it while the run goes on.
  std::shared_ptr<const MapCorrection> correction() const;

  // Keyframes handed over and not yet taken up by the worker. Any thread.
  std::size_t waiting() const;

  // The times of the keyframes found to revisit a kept keyframe's place (LoopConfig::
  // cover_radius_m, at corrected poses) since the last call: the tracker and the saved map need
  // not keep them either. Any thread.
  std::vector<std::int64_t> takeCovered();

 private:
  void work();
  // Publishes the graph's correction when it was optimised since the last one published.
  void publish();

  LoopGraph graph_;
  mutable std::mutex mutex_;
  std::condition_variable wake_;
  std::deque<std::shared_ptr<const fusion::KeyframeRecord>> queue_;
  bool finishing_ = false;
  mutable std::mutex published_mutex_;
  std::shared_ptr<const MapCorrection> published_;
  std::vector<std::int64_t> covered_ns_;  // guarded by published_mutex_
  std::thread worker_;
};

}  // namespace tessera::loop
