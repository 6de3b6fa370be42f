#include "stop_request.h"

#include <csignal>
#include <mutex>

#include <unistd.h>

namespace tessera::cli {

namespace {

std::atomic<bool> g_stop{false};

extern "C" void requestStop(int /*signal*/) {
  if (g_stop.exchange(true)) _exit(130);  // the second request: stop now
}

}  // namespace

const std::atomic<bool>& stopOnInterrupt() {
  static std::once_flag once;
  std::call_once(once, [] {
    std::signal(SIGINT, requestStop);
    std::signal(SIGTERM, requestStop);
  });
  return g_stop;
}

}  // namespace tessera::cli
