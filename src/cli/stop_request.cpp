#include "stop_request.h"

#include <signal.h>
#include <mutex>

#include <unistd.h>

namespace tessera::cli {

namespace {

std::atomic<bool> g_stop{false};

// Only a lock-free atomic may be touched from a signal handler.
static_assert(std::atomic<bool>::is_always_lock_free);

extern "C" void requestStop(int /*signal*/) {
  if (g_stop.exchange(true)) {
    // The second request: stop now. SQLite's journal keeps the database as it was after the
    // last committed patch.
    static const char kAbort[] = "\ntessera: aborted\n";
    (void)!write(STDERR_FILENO, kAbort, sizeof kAbort - 1);
    _exit(130);
  }
  // write(2) is async-signal-safe; the logger is not.
  static const char kStopping[] =
      "\ntessera: stopping: finishing and exporting the map (again to abort)\n";
  (void)!write(STDERR_FILENO, kStopping, sizeof kStopping - 1);
}

}  // namespace

const std::atomic<bool>& stopOnInterrupt() {
  static std::once_flag once;
  std::call_once(once, [] {
    struct sigaction action {};
    action.sa_handler = requestStop;
    sigemptyset(&action.sa_mask);
    action.sa_flags = SA_RESTART;  // a read interrupted by the signal goes on
    sigaction(SIGINT, &action, nullptr);
    sigaction(SIGTERM, &action, nullptr);
  });
  return g_stop;
}

}  // namespace tessera::cli
