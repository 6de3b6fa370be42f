#include "internal/background_workers.h"

#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>

#include <spdlog/spdlog.h>

namespace tessera::pipeline::internal {

BackgroundWorkers::BackgroundWorkers(int threads, int nice) : nice_(nice) {
  growTo(std::max(1, threads));
}

void BackgroundWorkers::growTo(int threads) {
  while (static_cast<int>(threads_.size()) < threads) {
    threads_.emplace_back([this] { work(nice_); });
  }
}

BackgroundWorkers::~BackgroundWorkers() {
  {
    const std::lock_guard lock(mutex_);
    stopping_ = true;
  }
  queued_.notify_all();
  for (std::thread& thread : threads_) thread.join();
}

void BackgroundWorkers::submit(std::function<void()> job) {
  {
    const std::lock_guard lock(mutex_);
    jobs_.push_back(std::move(job));
  }
  queued_.notify_one();
}

bool BackgroundWorkers::failed() {
  const std::lock_guard lock(mutex_);
  return first_error_ != nullptr;
}

void BackgroundWorkers::rethrowFirst() {
  const std::lock_guard lock(mutex_);
  if (first_error_) std::rethrow_exception(first_error_);
}

void lowerOwnPriority(int nice) {
  if (nice == 0) return;
  // On Linux a thread's nice value is its own: the thread's id names it to setpriority. It
  // starts at its creator's; raising it needs no privilege.
  const auto tid = static_cast<id_t>(::syscall(SYS_gettid));
  errno = 0;
  const int own = ::getpriority(PRIO_PROCESS, tid);
  if ((own == -1 && errno != 0) ||
      ::setpriority(PRIO_PROCESS, tid, std::min(19, own + nice)) != 0) {
    spdlog::debug("a background thread keeps the process's priority: {}", std::strerror(errno));
  }
}

void BackgroundWorkers::work(int nice) {
  lowerOwnPriority(nice);
  for (;;) {
    std::function<void()> job;
    {
      std::unique_lock lock(mutex_);
      queued_.wait(lock, [&] { return stopping_ || !jobs_.empty(); });
      if (jobs_.empty()) return;  // stopping, and nothing left
      job = std::move(jobs_.front());
      jobs_.pop_front();
    }
    try {
      job();
    } catch (...) {
      const std::lock_guard lock(mutex_);
      if (!first_error_) first_error_ = std::current_exception();
    }
  }
}

}  // namespace tessera::pipeline::internal
