#pragma once
// The host clock of Frame::arrival_ns: steady (monotonic), nanoseconds since its epoch.
#include <chrono>
#include <cstdint>

namespace tessera::core {

inline std::int64_t steadyNowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

}  // namespace tessera::core
