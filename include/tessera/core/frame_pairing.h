#pragma once
// Depth and colour frames on their way from a live device's threads to its source's reader,
// and the pairing of each depth frame with the colour frame nearest in time (the OpenNI2 and
// libfreenect sources share it).
#include <chrono>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <mutex>
#include <optional>

#include <opencv2/core/mat.hpp>

#include "tessera/core/frame_source.h"

namespace tessera::core {

// One image as the device's thread hands it over.
struct CapturedImage {
  std::int64_t stamp = 0;       // the device's clock, in its own units
  std::int64_t arrival_ns = 0;  // host steady clock (steadyNowNs)
  int device_index = 0;         // the device's frame number, where it gives one
  cv::Mat image;                // depth CV_16UC1 millimetres, or colour CV_8UC3 RGB
};

// Shared by the device's threads (writers) and the reader; every field is guarded by `mutex`.
struct PairingInbox {
  std::mutex mutex;
  std::condition_variable changed;
  std::deque<CapturedImage> depth;
  std::deque<CapturedImage> colour;
  std::size_t depth_capacity = 2;   // a busy reader loses the oldest depth frames
  std::size_t colour_capacity = 8;  // enough to pair with any depth frame still held
  std::size_t delivered = 0;        // depth frames the device sent
  std::size_t dropped = 0;          // ... that the reader never got
  bool lost = false;                // the device went away
  bool colour_started = false;      // a colour frame has come since the connection opened
  // A colour stream starts later than depth (a Kinect's by a few hundred ms, and a loaded
  // machine's threads later still): until its first frame has come, pairing waits this long.
  std::chrono::microseconds colour_start_wait = std::chrono::seconds(1);

  // Under `mutex`, and notifying the reader: a depth frame, after `missed` ones the device
  // sent that never arrived; the oldest held beyond capacity are dropped.
  void pushDepth(CapturedImage frame, std::size_t missed = 0);
  // The same for a colour frame, kept in stamp order among those held.
  void pushColour(CapturedImage frame);
  // Empties the queues for a new connection (the counts stay).
  void clearFrames();
  // How long a depth frame waits for its colour frame: `usual`, or colour_start_wait while the
  // colour stream has not started.
  std::chrono::microseconds colourWait(std::chrono::microseconds usual) const;
  // `stats` with the delivered and dropped counts filled in (takes the mutex).
  LiveStats withCounts(LiveStats stats);

  // With `lock` held on `mutex`: the colour frame nearest `stamp`, at most `tolerance` away,
  // after waiting up to `wait` for one at or after stamp - tolerance (it may not have come yet).
  // It and every older colour frame leave the queue. Nothing when there is none that near.
  std::optional<CapturedImage> takeColourNear(std::unique_lock<std::mutex>& lock,
                                              std::int64_t stamp, std::int64_t tolerance,
                                              std::chrono::microseconds wait);
};

}  // namespace tessera::core
