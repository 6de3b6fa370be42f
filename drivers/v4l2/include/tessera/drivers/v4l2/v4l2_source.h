#pragma once
// Live RGB-D frames from V4L2 nodes: a depth node and, optionally, a colour node, paired by
// their buffer timestamps. URIs are described in v4l2_uri.h, the user's view in docs/V4L2.md.
#include <cstdint>
#include <deque>
#include <memory>
#include <optional>
#include <string>

#include "tessera/core/frame_source.h"
#include "tessera/drivers/v4l2/camera_calibration.h"
#include "tessera/drivers/v4l2/v4l2_capture.h"
#include "tessera/drivers/v4l2/v4l2_uri.h"

namespace tessera::drivers::v4l2 {

struct V4l2Options {
  // Depth intrinsics (--intrinsics); win over the calibration file's. Needed when the URI has
  // neither a profile nor a calibration file.
  std::optional<core::Intrinsics> intrinsics;
  int buffer_count = 4;             // mmap streaming buffers per node
  int stall_timeout_ms = 2000;      // a node that delivers nothing for this long ends the stream
  double pair_tolerance_ms = 16.7;  // widest depth-colour gap: half a frame period at 30 Hz
  int pair_wait_ms = 100;           // how long a depth frame waits for colour to catch up
  DeviceFactory make_device;        // empty: the real nodes through libv4l2 (tests: a fake)
};

// Pairing: each depth frame takes the colour frame nearest in time, if it is within
// pair_tolerance_ms; a colour frame may serve two depth frames when colour runs slower.
// Colour frames too old for any later depth frame are dropped. A depth frame waits up to
// pair_wait_ms for the colour stream to pass its timestamp; one that still has no colour
// partner is a kBadFrame (not passed on without colour: fusion would paint it grey), and so is
// a short, flagged or undecodable frame of either node. The stream ends (kEndOfData with the
// node's path in `problem`) when either node disappears, fails or stalls. Both nodes must stamp
// buffers with one clock (the kernel's CLOCK_MONOTONIC, as UVC and v4l2loopback do).
// Frames are delivered in order; a reader slower than the camera gets older frames while the
// driver, its buffers full, drops the newest. Not thread-safe (one reader).
class V4l2Source : public core::FrameSource {
 public:
  // Throws core::ConfigError (malformed URI, bad calibration file, no intrinsics) or
  // core::SourceError (a node that cannot be opened or offers no usable format).
  explicit V4l2Source(const std::string& uri, const V4l2Options& options = {});
  ~V4l2Source() override;

  core::ReadResult read() override;
  std::string name() const override { return uri_; }
  bool isLive() const override { return true; }
  // Drops are the gaps in the depth node's frame sequence: frames the driver dropped because
  // every buffer was still waiting for a busy reader.
  core::LiveStats liveStats() const override { return stats_; }

  const core::Intrinsics& intrinsics() const { return intrinsics_; }
  bool hasColour() const { return colour_ != nullptr; }
  const V4l2Capture& depthCapture() const { return *depth_; }
  const V4l2Capture* colourCapture() const { return colour_.get(); }

 private:
  // Reads colour until it passes `timestamp_ns`; false when the colour stream ended.
  bool catchUpColour(std::int64_t timestamp_ns, std::string& end_problem);
  // The queued colour frame nearest to `timestamp_ns` within the tolerance, else none.
  std::optional<CaptureResult> takeColourFor(std::int64_t timestamp_ns, std::string& why_not);
  core::ReadResult endOfData(std::string problem);

  std::string uri_;
  V4l2Options options_;
  std::unique_ptr<V4l2Capture> depth_;
  std::unique_ptr<V4l2Capture> colour_;
  core::Intrinsics intrinsics_;
  std::optional<core::ColourCamera> colour_camera_;
  bool mirror_ = false;
  std::deque<CaptureResult> colour_queue_;  // oldest first
  std::string colour_problem_;              // the last bad colour frame, for the pairing message
  std::uint64_t frames_read_ = 0;
  std::optional<std::uint32_t> last_depth_sequence_;
  core::LiveStats stats_;
  bool ended_ = false;
};

// The factory the CLI calls for a v4l2:// SOURCE; throws as V4l2Source does.
std::unique_ptr<core::FrameSource> openV4l2Source(const std::string& uri,
                                                  const V4l2Options& options = {});

}  // namespace tessera::drivers::v4l2
