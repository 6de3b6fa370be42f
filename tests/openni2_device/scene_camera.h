#pragma once
// The camera the test OpenNI2 driver presents: a synthetic scene's frames, rendered once and
// then delivered at the scene's frame rate, with an optional unplug. Configured from the
// environment, so that a test can load the driver through OpenNI2 and still steer it:
//   TESSERA_TEST_DEVICE_SCENE      scene file (config/scenes/*.yaml); unset: no device at all
//   TESSERA_TEST_DEVICE_FRAMES     frames to play (default: the scene's)
//   TESSERA_TEST_DEVICE_FPS        delivery rate (default: the scene's, which the mode reports)
//   TESSERA_TEST_DEVICE_UNPLUG_AT  frame index at which the device disappears (default: never)
//   TESSERA_TEST_DEVICE_REPLUG_MS  how long it stays away (default: for good)
//   TESSERA_TEST_DEVICE_PLAYS      times the frames are played, forth and back (default: 1), so
//                                  that a long stream needs only a few frames rendered
//   TESSERA_TEST_DEVICE_COLOUR_UNTIL  deliveries that carry colour (default: all); after them
//                                  only depth comes, as from a device whose colour camera stalls
// After its last frame the device disappears for good, so every live run ends.
#include <chrono>
#include <cstdint>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include <opencv2/core/mat.hpp>

#include "tessera/core/intrinsics.h"

namespace tessera::test {

struct CameraSettings {
  std::string scene_file;
  std::optional<int> frames;
  std::optional<double> fps;
  std::optional<int> unplug_at;
  std::optional<int> replug_ms;
  int plays = 1;
  std::optional<int> colour_until;

  // Nothing when TESSERA_TEST_DEVICE_SCENE is unset.
  static std::optional<CameraSettings> fromEnvironment();
};

struct RenderedFrame {
  std::uint64_t timestamp_us = 0;
  cv::Mat depth_mm;  // CV_16UC1
  cv::Mat rgb;       // CV_8UC3
};

// Thread-safe: OpenNI2 calls the driver from its own threads and the device's emitter.
class SceneCamera {
 public:
  explicit SceneCamera(CameraSettings settings);

  // Renders every frame on first use (the driver's deviceOpen), so that delivery keeps time.
  void renderIfNeeded();
  // Delivery `number` (0, 1, ...): the rendered frame it shows and its own time stamp.
  const RenderedFrame& frame(int number) const;
  std::uint64_t timestampUs(int number) const;
  bool hasColour(int number) const {
    return !settings_.colour_until || number < *settings_.colour_until;
  }
  double fps() const { return fps_; }        // delivery rate
  int modeFps() const { return mode_fps_; }  // the scene's rate, as the mode says
  const core::Intrinsics& intrinsics() const { return intrinsics_; }
  bool colourRegistered() const { return colour_registered_; }
  std::string uri() const { return "tessera-test://" + scene_name_; }

  // The delivery number of the next frame; nothing while unplugged or once every frame is out.
  // `unplugged` is set when this call is the moment the device goes away.
  std::optional<int> nextFrame(bool& unplugged);
  // True unless unplugged; a replugged device resumes where the scene has got to meanwhile.
  bool present();
  // When an unplugged device comes back; nothing when it is present or gone for good.
  std::optional<std::chrono::steady_clock::time_point> backAt();

 private:
  CameraSettings settings_;
  std::mutex mutex_;
  std::vector<RenderedFrame> frames_;
  int frame_count_ = 0;
  double fps_ = 30.0;
  double scene_fps_ = 30.0;
  int mode_fps_ = 30;
  core::Intrinsics intrinsics_;
  bool colour_registered_ = true;
  std::string scene_name_;
  int next_ = 0;
  bool gone_for_good_ = false;
  std::optional<std::chrono::steady_clock::time_point> back_at_;
};

}  // namespace tessera::test
