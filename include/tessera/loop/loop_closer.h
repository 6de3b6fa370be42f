#pragma once
// Runs loop closure (loop_graph.h) on its own thread, off the frame path: the tracking stage
// hands over keyframes without waiting, and the run reads the corrected trajectory at the end.
//
// Thread-safety: add() from one thread (the tracking stage); finish() and the readers after
// the stream has ended.
#include <condition_variable>
#include <deque>
#include <memory>
#include <mutex>
#include <thread>

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

 private:
  void work();

  LoopGraph graph_;
  std::mutex mutex_;
  std::condition_variable wake_;
  std::deque<std::shared_ptr<const fusion::KeyframeRecord>> queue_;
  bool finishing_ = false;
  std::thread worker_;
};

}  // namespace tessera::loop
