#pragma once
// Threads of lower scheduling priority for the patch path (describing and committing
// textures): when the cores are short, the kernel gives them to the frame path first, so a
// live run defers texturing before it drops frames, while idle cores still do the texturing
// at full speed. Jobs run in the order they were queued; with one thread, one at a time.
#include <condition_variable>
#include <cstddef>
#include <deque>
#include <exception>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

namespace tessera::pipeline::internal {

// Raises the calling thread's nice value by `nice` (at most to 19; 0: leaves it).
void lowerOwnPriority(int nice);

class BackgroundWorkers {
 public:
  // `threads` threads, their nice value raised by `nice` (at most to 19) above the creating
  // thread's (0: the same priority). Linux gives each thread its own.
  BackgroundWorkers(int threads, int nice);
  ~BackgroundWorkers();  // finishes the queued jobs, then joins
  BackgroundWorkers(const BackgroundWorkers&) = delete;
  BackgroundWorkers& operator=(const BackgroundWorkers&) = delete;

  // Queues a job. A job that throws is not retried: its exception is kept for rethrowFirst().
  void submit(std::function<void()> job);
  // Rethrows the first exception a job threw, if any.
  void rethrowFirst();
  // Whether a job threw.
  bool failed();
  // Starts threads, at the same nice value, until there are `threads` (never fewer than now).
  void growTo(int threads);

 private:
  void work(int nice);

  std::mutex mutex_;
  std::condition_variable queued_;
  std::deque<std::function<void()>> jobs_;
  bool stopping_ = false;
  std::exception_ptr first_error_;
  const int nice_;
  std::vector<std::thread> threads_;
};

}  // namespace tessera::pipeline::internal
