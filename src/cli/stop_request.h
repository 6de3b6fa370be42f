#pragma once
// Ctrl-C (SIGINT) and SIGTERM end a live run cleanly: the stream stops, the map is exported.
// A second Ctrl-C ends the process at once.
#include <atomic>

namespace tessera::cli {

// Installs the handlers (once) and returns the flag they set.
const std::atomic<bool>& stopOnInterrupt();

}  // namespace tessera::cli
