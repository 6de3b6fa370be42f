#pragma once
// Ctrl-C (SIGINT) and SIGTERM end a run (live or replay) cleanly: the input stops, the live
// patches are finalized and textured, the graph drains and the map is exported. A second
// signal ends the process at once; the database keeps every patch committed before it.
#include <atomic>

namespace tessera::cli {

// Installs the handlers (once) and returns the flag they set.
const std::atomic<bool>& stopOnInterrupt();

}  // namespace tessera::cli
