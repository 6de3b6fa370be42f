#pragma once
// Live progress: on a terminal one line redrawn in place (frames, frames/s, map size, patches,
// texture bytes before -> after, compression, drops, latency); in a log (stderr not a
// terminal) the same figures as a plain line every 10 s.
#include <chrono>
#include <string>

#include "tessera/pipeline/map_monitor.h"
#include "tessera/pipeline/stages.h"

namespace tessera::cli {

// Called from the pipeline's sink (one thread at a time).
class ProgressLine {
 public:
  // `monitor`, when given, adds the map's figures (a recording has none); `quiet`: draws and
  // logs nothing.
  explicit ProgressLine(const pipeline::MapMonitor* monitor = nullptr, bool quiet = false);
  void update(const pipeline::Progress& progress);
  // Ends the line so that later output starts on a fresh one.
  void finish();

  // The figures of one line, without terminal control characters.
  static std::string describe(const pipeline::Progress& progress,
                              const pipeline::MonitorSnapshot* snapshot);

 private:
  std::string line(const pipeline::Progress& progress) const;

  const pipeline::MapMonitor* monitor_;
  bool quiet_;
  bool terminal_;
  bool drawn_ = false;
  std::chrono::steady_clock::time_point last_draw_;
};

}  // namespace tessera::cli
