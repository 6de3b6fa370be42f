#include "progress_line.h"

#include <unistd.h>

#include <cstdio>

#include <fmt/format.h>

namespace tessera::cli {

ProgressLine::ProgressLine() : enabled_(isatty(STDERR_FILENO) == 1) {}

void ProgressLine::update(const pipeline::Progress& progress) {
  if (!enabled_) return;
  const auto now = std::chrono::steady_clock::now();
  const bool last = progress.frames_total && progress.frames_done == *progress.frames_total;
  if (drawn_ && !last && now - last_draw_ < std::chrono::milliseconds(100)) return;
  last_draw_ = now;
  drawn_ = true;
  const double fps = progress.elapsed_s > 0.0
                         ? static_cast<double>(progress.frames_done) / progress.elapsed_s
                         : 0.0;
  const std::string total =
      progress.frames_total ? fmt::format("/{}", *progress.frames_total) : std::string();
  const std::string latency =
      progress.latency_ms ? fmt::format("  latency {:.0f} ms", *progress.latency_ms) : "";
  fmt::print(stderr, "\r\033[K  frame {}{}  {:.1f} frames/s  map {:.1f} MB{}", progress.frames_done,
             total, fps, static_cast<double>(progress.map_bytes) / 1e6, latency);
  std::fflush(stderr);
}

void ProgressLine::finish() {
  if (drawn_) fmt::print(stderr, "\n");
  drawn_ = false;
}

}  // namespace tessera::cli
