#pragma once
// Frames as libfreenect's event loop hands them over, held for the reader of the source.
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <mutex>
#include <string>

#include <libfreenect.h>
#include <opencv2/core/mat.hpp>

namespace tessera::drivers::freenect {

struct CapturedFrame {
  std::int64_t ticks = 0;       // device clock (kinect_v1.h), unwrapped to 64 bits
  std::int64_t arrival_ns = 0;  // host steady clock
  cv::Mat image;                // depth CV_16UC1 millimetres, or colour CV_8UC3 RGB
};

// Extends the device's 32-bit timestamps to 64 bits across wrap-arounds. Depth and colour
// share one clock and may arrive slightly out of order, so each stamp is placed nearest the
// previous one (a step of less than 2^31 ticks either way).
class DeviceClock {
 public:
  std::int64_t unwrap(std::uint32_t stamp);

 private:
  bool started_ = false;
  std::uint32_t last_stamp_ = 0;
  std::int64_t last_ticks_ = 0;
};

// Shared by libfreenect's event-loop thread (callbacks, writer) and the source's reader. The
// format fields are set before the event loop starts and only read afterwards; every other
// field is guarded by `mutex`.
struct FrameInbox {
  bool depth_in_mm = false;      // FREENECT_DEPTH_REGISTERED, else raw 11-bit disparity
  std::size_t depth_bytes = 0;   // of one frame as libfreenect sends it
  std::size_t colour_bytes = 0;  // of one FREENECT_VIDEO_RGB frame

  std::mutex mutex;
  std::condition_variable changed;
  std::deque<CapturedFrame> depth;
  std::deque<CapturedFrame> colour;
  std::size_t depth_capacity = 2;   // a busy reader loses the oldest depth frames
  std::size_t colour_capacity = 8;  // enough to pair with any depth frame still held
  std::size_t delivered = 0;
  std::size_t dropped = 0;
  DeviceClock clock;
  bool lost = false;  // the event loop failed: unplugged, or the fakenect dump ended
  int loss_code = 0;  // what freenect_process_events returned

  void clear();  // for a new connection: no frames, a fresh clock, not lost
};

// The freenect_depth_cb / freenect_video_cb: the device's user data is the FrameInbox.
void onDepth(freenect_device* device, void* data, std::uint32_t timestamp);
void onColour(freenect_device* device, void* data, std::uint32_t timestamp);

}  // namespace tessera::drivers::freenect
