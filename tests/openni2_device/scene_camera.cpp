#include "scene_camera.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>

#include "tessera/drivers/synthetic/renderer.h"

namespace tessera::test {

namespace {

std::optional<double> numberFromEnvironment(const char* name) {
  const char* value = std::getenv(name);
  if (value == nullptr || *value == '\0') return std::nullopt;
  return std::strtod(value, nullptr);
}

std::optional<int> integerFromEnvironment(const char* name) {
  const std::optional<double> value = numberFromEnvironment(name);
  if (!value) return std::nullopt;
  return static_cast<int>(*value);
}

}  // namespace

std::optional<CameraSettings> CameraSettings::fromEnvironment() {
  const char* scene = std::getenv("TESSERA_TEST_DEVICE_SCENE");
  if (scene == nullptr || *scene == '\0') return std::nullopt;
  CameraSettings settings;
  settings.scene_file = scene;
  settings.frames = integerFromEnvironment("TESSERA_TEST_DEVICE_FRAMES");
  settings.fps = numberFromEnvironment("TESSERA_TEST_DEVICE_FPS");
  settings.unplug_at = integerFromEnvironment("TESSERA_TEST_DEVICE_UNPLUG_AT");
  settings.replug_ms = integerFromEnvironment("TESSERA_TEST_DEVICE_REPLUG_MS");
  settings.plays = std::max(1, integerFromEnvironment("TESSERA_TEST_DEVICE_PLAYS").value_or(1));
  settings.colour_until = integerFromEnvironment("TESSERA_TEST_DEVICE_COLOUR_UNTIL");
  return settings;
}

SceneCamera::SceneCamera(CameraSettings settings) : settings_(std::move(settings)) {
  const drivers::synthetic::Scene scene = drivers::synthetic::loadScene(settings_.scene_file);
  scene_name_ = scene.name;
  frame_count_ = std::min(settings_.frames.value_or(scene.frames), scene.frames);
  fps_ = settings_.fps.value_or(scene.fps);
  scene_fps_ = scene.fps;
  mode_fps_ = static_cast<int>(std::lround(scene.fps));
  intrinsics_ = scene.sensor.intrinsics;
  colour_registered_ = scene.sensor.colour_registered;
}

void SceneCamera::renderIfNeeded() {
  std::lock_guard lock(mutex_);
  if (!frames_.empty()) return;
  // One ray per pixel (the recordings use 2 x 2): a test waits for this at device open.
  namespace synthetic = drivers::synthetic;
  const synthetic::Scene scene = synthetic::loadScene(settings_.scene_file);
  for (int i = 0; i < frame_count_; ++i) {
    const core::Isometry T_W_C = scene.cameraPose(i);
    synthetic::CleanView view = synthetic::renderClean(scene, intrinsics_, T_W_C, 1);
    if (!colour_registered_) {
      // Colour from its own camera beside the depth camera, as the scene's sensor has it.
      core::Isometry T_D_RGB = core::Isometry::Identity();
      T_D_RGB.translation().x() = scene.sensor.colour_baseline_m;
      view.colour = synthetic::renderClean(scene, intrinsics_, T_W_C * T_D_RGB, 1).colour;
    }
    RenderedFrame frame;
    frame.timestamp_us = static_cast<std::uint64_t>(scene.timestampNs(i) / 1000);
    synthetic::applySensor(scene.sensor, view, scene.seed * 1'000'003ULL + static_cast<unsigned>(i),
                           frame.depth_mm, frame.rgb);
    frames_.push_back(std::move(frame));
  }
}

std::optional<int> SceneCamera::nextFrame(bool& unplugged) {
  std::lock_guard lock(mutex_);
  unplugged = false;
  if (gone_for_good_) return std::nullopt;
  if (back_at_) {
    if (std::chrono::steady_clock::now() < *back_at_) return std::nullopt;
    back_at_.reset();
  }
  if (next_ >= frame_count_ * settings_.plays) {
    gone_for_good_ = unplugged = true;
    return std::nullopt;
  }
  if (settings_.unplug_at && next_ == *settings_.unplug_at) {
    settings_.unplug_at.reset();  // once
    unplugged = true;
    if (!settings_.replug_ms) {
      gone_for_good_ = true;
      return std::nullopt;
    }
    // The scene goes on while the device is away: the frames of that time are never seen.
    back_at_ = std::chrono::steady_clock::now() + std::chrono::milliseconds(*settings_.replug_ms);
    next_ += static_cast<int>(std::lround(*settings_.replug_ms * fps_ / 1000.0));
    return std::nullopt;
  }
  return next_++;
}

const RenderedFrame& SceneCamera::frame(int number) const {
  // Played forth and back (0 .. n-1, n-2 .. 1, 0 ..), so that the camera never jumps.
  const int period = std::max(1, 2 * (frame_count_ - 1));
  const int k = number % period;
  return frames_[static_cast<std::size_t>(k < frame_count_ ? k : period - k)];
}

std::uint64_t SceneCamera::timestampUs(int number) const {
  if (number < frame_count_) return frames_[static_cast<std::size_t>(number)].timestamp_us;
  // Later plays go on at the scene's own rate from its last frame.
  return frames_.back().timestamp_us +
         static_cast<std::uint64_t>(std::llround((number - frame_count_ + 1) * 1e6 / scene_fps_));
}

bool SceneCamera::present() {
  std::lock_guard lock(mutex_);
  if (gone_for_good_) return false;
  return !back_at_ || std::chrono::steady_clock::now() >= *back_at_;
}

std::optional<std::chrono::steady_clock::time_point> SceneCamera::backAt() {
  std::lock_guard lock(mutex_);
  return back_at_;
}

}  // namespace tessera::test
