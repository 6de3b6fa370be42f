#pragma once
// A one-line live progress display for terminals: frames, frames/s and map size.
#include <chrono>

#include "tessera/pipeline/stages.h"

namespace tessera::cli {

// Called from the pipeline's sink (one thread at a time).
class ProgressLine {
 public:
  // Draws nothing unless stderr is a terminal.
  ProgressLine();
  void update(const pipeline::Progress& progress);
  // Ends the line so that later output starts on a fresh one.
  void finish();

 private:
  bool enabled_;
  bool drawn_ = false;
  std::chrono::steady_clock::time_point last_draw_;
};

}  // namespace tessera::cli
