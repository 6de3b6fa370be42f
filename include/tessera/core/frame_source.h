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
  // No frame now: the live device went away (`problem` says how). The next read() waits for it
  // to come back and ends the stream if it does not.
  kInterrupted,
};

struct ReadResult {
  ReadStatus status = ReadStatus::kEndOfData;
  Frame frame;
  std::string problem;
};

// What a live source counts while it streams.
struct LiveStats {
  std::size_t frames_delivered = 0;  // depth frames the device sent
  std::size_t frames_dropped = 0;    // of those, never read: the pipeline was busy
  std::size_t device_losses = 0;     // unplugged or stalled
  std::size_t reconnects = 0;        // losses after which the device came back
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
  // A live device keeps sending whether or not it is read: the pipeline must not fall behind
  // (it drops frames instead of queueing them). Recordings wait for the reader.
  virtual bool isLive() const { return false; }
  virtual LiveStats liveStats() const { return {}; }
  // The reader is done (end of stream, --max-frames, Ctrl-C): a live device stops sending, its
  // recording closes, and frames still queued count as dropped. read() then ends the stream.
  virtual void stopStreaming() {}
};

}  // namespace tessera::core
