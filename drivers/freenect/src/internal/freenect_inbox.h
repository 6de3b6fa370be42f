#pragma once
// Frames as libfreenect's event loop hands them over, held for the reader of the source.
#include <cstddef>
#include <cstdint>
#include <string>

#include <libfreenect.h>

#include "tessera/core/frame_pairing.h"

namespace tessera::drivers::freenect {

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
// field is guarded by `mutex`. Stamps are device ticks (kinect_v1.h) unwrapped to 64 bits;
// `lost`: the event loop failed (unplugged, or the fakenect dump ended).
struct FrameInbox : core::PairingInbox {
  bool depth_in_mm = false;      // FREENECT_DEPTH_REGISTERED, else raw 11-bit disparity
  std::size_t depth_bytes = 0;   // of one frame as libfreenect sends it
  std::size_t colour_bytes = 0;  // of one FREENECT_VIDEO_RGB frame

  DeviceClock clock;
  int loss_code = 0;  // what freenect_process_events returned

  void clear();  // for a new connection: no frames, a fresh clock, not lost
};

// The freenect_depth_cb / freenect_video_cb: the device's user data is the FrameInbox.
void onDepth(freenect_device* device, void* data, std::uint32_t timestamp);
void onColour(freenect_device* device, void* data, std::uint32_t timestamp);

}  // namespace tessera::drivers::freenect
