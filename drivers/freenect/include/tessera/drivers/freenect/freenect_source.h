#pragma once
// Live frames from a Kinect v1 through libfreenect's asynchronous API (docs/FREENECT.md).
// URIs: `freenect://` opens the first device, `freenect://N` the device of index N (from 0).
// Debian's fakenect library replays a recorded dump in place of the device; the source works
// the same against it (the tests use it).
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "tessera/core/frame.h"
#include "tessera/core/frame_source.h"

namespace tessera::drivers::freenect {

struct FreenectOptions {
  // Overrides the typical Kinect v1 intrinsics of the depth image (kinect_v1.h).
  std::optional<core::Intrinsics> intrinsics;
  // Overrides the typical colour camera used when libfreenect cannot register depth to colour
  // (fakenect offers only raw 11-bit disparity). Ignored when the depth is registered.
  std::optional<core::ColourCamera> colour_camera;
  int frame_timeout_ms = 2000;        // no depth frame for this long: the stream has stalled
  double reconnect_timeout_s = 10.0;  // how long a lost device is waited for
  std::size_t queue_frames = 2;       // frames held for a busy pipeline; older ones are dropped
};

// The device index in "freenect://" (0) or "freenect://N"; nothing for other sources.
// Throws core::ConfigError naming the URI when the part after the scheme is not an index.
std::optional<int> parseFreenectUri(const std::string& uri);

// Depth frames in millimetres paired with the RGB frame of the nearest device timestamp; no
// mirroring (libfreenect delivers the camera's own view). Depth is registered to colour by
// libfreenect (FREENECT_DEPTH_REGISTERED) when the library offers it; otherwise raw disparity
// is converted to millimetres and frames carry the colour camera for host-side registration.
// A device that stops sending gives one kInterrupted result; the next read() retries with
// growing pauses (0.1 s doubling to 2 s) for reconnect_timeout_s, then resumes or ends the
// stream naming the device. read() is for one thread; the source's own thread runs
// libfreenect's event loop. One source at a time per process (fakenect's state is global).
// Throws core::ConfigError for a malformed URI and core::SourceError naming the device when it
// cannot be opened (no such index, no access, a fakenect dump that cannot be replayed).
std::unique_ptr<core::FrameSource> openFreenectSource(const std::string& uri,
                                                      const FreenectOptions& options);

// `tessera devices`: one line per Kinect v1 libfreenect finds, "freenect://N" followed by the
// camera serial when the library can report it (fakenect cannot; it names its dump instead).
// Throws core::SourceError when libfreenect cannot start.
std::vector<std::string> listFreenectDevices();

}  // namespace tessera::drivers::freenect
