#pragma once
// The interface every driver implements: recordings, dataset folders and live devices.
#include <cstddef>
#include <optional>
#include <string>

#include "tessera/core/frame.h"

namespace tessera::core {

enum class ReadStatus {
  kFrame,      // `frame` holds the next frame
  kBadFrame,   // this frame could not be read; `problem` says why; reading may go on
  kEndOfData,  // no more frames; `problem` is empty unless the data ended abnormally
};

struct ReadResult {
  ReadStatus status = ReadStatus::kEndOfData;
  Frame frame;
  std::string problem;
};

// Not thread-safe: one caller (the pipeline's source node) reads at a time.
class FrameSource {
 public:
  virtual ~FrameSource() = default;

  virtual ReadResult read() = 0;
  // A short human-readable name: the folder, file or device URI.
  virtual std::string name() const = 0;
  // Number of frames when known in advance (recordings), for progress display.
  virtual std::optional<std::size_t> frameCount() const { return std::nullopt; }
};

}  // namespace tessera::core
