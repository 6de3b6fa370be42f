#pragma once
// Live frames from an OpenNI2 device (Kinect v1, Xtion, Carmine, or any device an OpenNI2
// driver presents). URIs: `openni2://` opens the first device, `openni2://URI` that device.
#include <atomic>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>

#include "tessera/core/frame_source.h"

namespace tessera::drivers::openni2 {

struct VideoModeRequest {
  int width = 640;
  int height = 480;
  int fps = 30;
  std::string describe() const;
};

// Parses "WIDTHxHEIGHT@FPS" (e.g. 640x480@30); throws core::ConfigError naming the value.
VideoModeRequest parseVideoMode(const std::string& text);

struct OpenNi2Options {
  std::string uri;  // the device's OpenNI2 URI; empty: the first device
  VideoModeRequest depth_mode;
  VideoModeRequest colour_mode;
  // Overrides the intrinsics derived from the depth stream's field of view.
  std::optional<core::Intrinsics> intrinsics;
  // Host-side registration when the device cannot register colour to depth itself: the colour
  // camera's intrinsics and pose (--calibration). Ignored when hardware registration works.
  std::optional<core::ColourCamera> colour_camera;
  int frame_timeout_ms = 2000;        // no depth frame for this long: the stream has stalled
  double reconnect_timeout_s = 10.0;  // how long a lost device is waited for
  std::size_t queue_frames = 2;       // frames held for a busy pipeline; older ones are dropped
  // Records what the device sends through OpenNI2's own Recorder (lossless), with an
  // OUT.gt.json sidecar holding the intrinsics. After a reconnect: OUT-2.oni, OUT-3.oni...
  std::filesystem::path record_path;
  // Set (e.g. by Ctrl-C) to end the stream: waits for frames or for a lost device end early.
  const std::atomic<bool>* stop = nullptr;
};

// The URI inside "openni2://URI" (empty for the first device); nothing for other sources.
std::optional<std::string> parseOpenNi2Uri(const std::string& source);

// Depth frames paired with the colour frame of the nearest timestamp, mirroring off, colour
// registered to depth by the device when it can. A device that is unplugged or stalls gives
// one kInterrupted result; the next read() retries with growing pauses (0.1 s doubling to 2 s)
// for reconnect_timeout_s, then resumes or ends the stream naming the device.
// read() is for one thread; OpenNI2's own threads fill the frame queues.
class OpenNi2Source : public core::FrameSource {
 public:
  // Throws core::SourceError naming the device (none found, cannot open, mode not offered:
  // the message lists the modes that are).
  explicit OpenNi2Source(const OpenNi2Options& options);
  ~OpenNi2Source() override;

  core::ReadResult read() override;
  std::string name() const override;
  bool isLive() const override { return true; }
  core::LiveStats liveStats() const override;
  void stopStreaming() override;

  const core::Intrinsics& intrinsics() const;
  bool hardwareRegistration() const;

 private:
  struct State;
  std::unique_ptr<State> state_;
};

}  // namespace tessera::drivers::openni2
