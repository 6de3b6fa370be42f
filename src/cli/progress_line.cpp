#include "progress_line.h"

#include <unistd.h>

#include <cstdio>

#include <fmt/format.h>
#include <spdlog/spdlog.h>

namespace tessera::cli {

namespace {
constexpr auto kRedraw = std::chrono::milliseconds(100);
constexpr auto kLogEvery = std::chrono::seconds(10);
}  // namespace

ProgressLine::ProgressLine(const pipeline::MapMonitor* monitor, bool quiet)
    : monitor_(monitor), quiet_(quiet), terminal_(isatty(STDERR_FILENO) == 1),
      last_draw_(std::chrono::steady_clock::now()) {}

std::string ProgressLine::describe(const pipeline::Progress& progress,
                                   const pipeline::MonitorSnapshot* snapshot) {
  const double fps = progress.elapsed_s > 0.0
                         ? static_cast<double>(progress.frames_done) / progress.elapsed_s
                         : 0.0;
  const std::string total =
      progress.frames_total ? fmt::format("/{}", *progress.frames_total) : std::string();
  std::string line = fmt::format("frame {}{}  {:.1f} frames/s  map {:.1f} MB", progress.frames_done,
                                 total, fps, static_cast<double>(progress.map_bytes) / 1e6);
  if (snapshot != nullptr) {
    const reuse::Economy& economy = snapshot->commits.economy;
    const pipeline::FrameFigures& frame = snapshot->frame.figures;
    line +=
        fmt::format("  patches {} live, {} final  textures {:.1f} -> {:.1f} MB", frame.patches_live,
                    frame.patches_finalized, 3e-6 * static_cast<double>(economy.pixels_before),
                    3e-6 * static_cast<double>(economy.pixels_after));
    if (economy.pixels_after > 0) {
      line += fmt::format(" ({:.1f}x)", static_cast<double>(economy.pixels_before) /
                                            static_cast<double>(economy.pixels_after));
    }
    if (snapshot->frame.frames_dropped > 0 || progress.latency_ms) {
      line += fmt::format("  drops {}", snapshot->frame.frames_dropped);
    }
  }
  if (progress.latency_ms) line += fmt::format("  latency {:.0f} ms", *progress.latency_ms);
  return line;
}

void ProgressLine::update(const pipeline::Progress& progress) {
  if (quiet_) return;
  const auto now = std::chrono::steady_clock::now();
  const bool last = progress.frames_total && progress.frames_done == *progress.frames_total;
  if (!terminal_) {
    if (now - last_draw_ < kLogEvery) return;
    last_draw_ = now;
    spdlog::info("{}", line(progress));
    return;
  }
  if (drawn_ && !last && now - last_draw_ < kRedraw) return;
  last_draw_ = now;
  drawn_ = true;
  fmt::print(stderr, "\r\033[K  {}", line(progress));
  std::fflush(stderr);
}

std::string ProgressLine::line(const pipeline::Progress& progress) const {
  if (monitor_ == nullptr) return describe(progress, nullptr);
  const pipeline::MonitorSnapshot snapshot = monitor_->snapshot();
  return describe(progress, &snapshot);
}

void ProgressLine::finish() {
  if (drawn_) fmt::print(stderr, "\n");
  drawn_ = false;
}

}  // namespace tessera::cli
