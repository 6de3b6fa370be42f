// A small OpenNI2 driver that presents a synthetic scene as a depth + colour device, so the
// live OpenNI2 path (device listing, modes, registration, mirroring, unplug and replug, OpenNI2's
// Recorder) runs in tests without hardware. Tests load it from a private driver folder.
#define XN_NEW(type, ...) new type(__VA_ARGS__)
#define XN_DELETE(p) delete (p)
#include <openni2/Driver/OniDriverAPI.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstring>
#include <memory>
#include <mutex>
#include <thread>
#include <vector>

#include <opencv2/core.hpp>

#include "scene_camera.h"

namespace {

using tessera::test::SceneCamera;

constexpr OniImageRegistrationMode kNoRegistration = ONI_IMAGE_REGISTRATION_OFF;

class SceneStream : public oni::driver::StreamBase {
 public:
  SceneStream(OniSensorType type, OniVideoMode mode, const SceneCamera& camera)
      : type_(type), mode_(mode), camera_(camera) {}

  OniStatus start() override {
    started_ = true;
    return ONI_STATUS_OK;
  }
  void stop() override { started_ = false; }
  bool started() const { return started_; }
  OniSensorType type() const { return type_; }

  OniBool isPropertySupported(int id) override {
    switch (id) {
      case ONI_STREAM_PROPERTY_VIDEO_MODE:
      case ONI_STREAM_PROPERTY_CROPPING:
      case ONI_STREAM_PROPERTY_HORIZONTAL_FOV:
      case ONI_STREAM_PROPERTY_VERTICAL_FOV:
      case ONI_STREAM_PROPERTY_MAX_VALUE:
      case ONI_STREAM_PROPERTY_MIN_VALUE:
      case ONI_STREAM_PROPERTY_STRIDE:
      case ONI_STREAM_PROPERTY_MIRRORING:
        return TRUE;
      default:
        return FALSE;
    }
  }

  OniStatus getProperty(int id, void* data, int* size) override {
    const tessera::core::Intrinsics& k = camera_.intrinsics();
    switch (id) {
      case ONI_STREAM_PROPERTY_VIDEO_MODE:
        return put(mode_, data, size);
      case ONI_STREAM_PROPERTY_CROPPING:
        return put(OniCropping{0, 0, 0, mode_.resolutionX, mode_.resolutionY}, data, size);
      case ONI_STREAM_PROPERTY_HORIZONTAL_FOV:
        return put(static_cast<float>(2.0 * std::atan(k.width / (2.0 * k.fx))), data, size);
      case ONI_STREAM_PROPERTY_VERTICAL_FOV:
        return put(static_cast<float>(2.0 * std::atan(k.height / (2.0 * k.fy))), data, size);
      case ONI_STREAM_PROPERTY_MAX_VALUE:
        return put(type_ == ONI_SENSOR_DEPTH ? 10000 : 255, data, size);
      case ONI_STREAM_PROPERTY_MIN_VALUE:
        return put(0, data, size);
      case ONI_STREAM_PROPERTY_STRIDE:
        return put(mode_.resolutionX * bytesPerPixel(), data, size);
      case ONI_STREAM_PROPERTY_MIRRORING:
        return put(static_cast<OniBool>(mirroring_ ? TRUE : FALSE), data, size);
      default:
        return ONI_STATUS_NOT_SUPPORTED;
    }
  }

  OniStatus setProperty(int id, const void* data, int size) override {
    if (id == ONI_STREAM_PROPERTY_MIRRORING && size == sizeof(OniBool)) {
      mirroring_ = *static_cast<const OniBool*>(data) == TRUE;
      return ONI_STATUS_OK;
    }
    if (id == ONI_STREAM_PROPERTY_VIDEO_MODE && size == sizeof(OniVideoMode)) {
      const auto* mode = static_cast<const OniVideoMode*>(data);
      // One mode per sensor: anything else is refused, as a real device refuses it.
      if (std::memcmp(mode, &mode_, sizeof(OniVideoMode)) != 0) return ONI_STATUS_NOT_SUPPORTED;
      return ONI_STATUS_OK;
    }
    return ONI_STATUS_NOT_SUPPORTED;
  }

  // Hands one frame of the scene to OpenNI2; mirrored when mirroring is on, as a Kinect is.
  void deliver(const cv::Mat& image, int index, std::uint64_t timestamp_us) {
    OniFrame* frame = getServices().acquireFrame();
    if (frame == nullptr) return;
    cv::Mat out(mode_.resolutionY, mode_.resolutionX, image.type(), frame->data);
    if (mirroring_) {
      cv::flip(image, out, 1);
    } else {
      image.copyTo(out);
    }
    frame->dataSize = static_cast<int>(image.total() * image.elemSize());
    frame->sensorType = type_;
    frame->timestamp = timestamp_us;
    frame->frameIndex = index + 1;  // OpenNI frame numbers start at 1
    frame->width = mode_.resolutionX;
    frame->height = mode_.resolutionY;
    frame->videoMode = mode_;
    frame->croppingEnabled = FALSE;
    frame->cropOriginX = frame->cropOriginY = 0;
    frame->stride = mode_.resolutionX * bytesPerPixel();
    raiseNewFrame(frame);
    getServices().releaseFrame(frame);
  }

 private:
  template <typename T>
  static OniStatus put(const T& value, void* data, int* size) {
    if (*size < static_cast<int>(sizeof(T))) return ONI_STATUS_BAD_PARAMETER;
    std::memcpy(data, &value, sizeof(T));
    *size = sizeof(T);
    return ONI_STATUS_OK;
  }
  int bytesPerPixel() const { return type_ == ONI_SENSOR_DEPTH ? 2 : 3; }

  OniSensorType type_;
  OniVideoMode mode_;
  const SceneCamera& camera_;
  std::atomic<bool> started_{false};
  std::atomic<bool> mirroring_{true};
};

class SceneDevice : public oni::driver::DeviceBase {
 public:
  using LostCallback = void (*)(void* cookie);

  SceneDevice(SceneCamera& camera, LostCallback on_lost, void* cookie)
      : camera_(camera), on_lost_(on_lost), cookie_(cookie) {
    const auto& k = camera.intrinsics();
    depth_mode_ = {ONI_PIXEL_FORMAT_DEPTH_1_MM, k.width, k.height, camera.modeFps()};
    colour_mode_ = {ONI_PIXEL_FORMAT_RGB888, k.width, k.height, depth_mode_.fps};
    sensors_[0] = {ONI_SENSOR_DEPTH, 1, &depth_mode_};
    sensors_[1] = {ONI_SENSOR_COLOR, 1, &colour_mode_};
    emitter_ = std::thread([this] { emit(); });
  }
  ~SceneDevice() override {
    stop_ = true;
    emitter_.join();
  }

  OniStatus getSensorInfoList(OniSensorInfo** infos, int* count) override {
    *infos = sensors_;
    *count = 2;
    return ONI_STATUS_OK;
  }

  oni::driver::StreamBase* createStream(OniSensorType type) override {
    if (type != ONI_SENSOR_DEPTH && type != ONI_SENSOR_COLOR) return nullptr;
    auto stream = std::make_shared<SceneStream>(
        type, type == ONI_SENSOR_DEPTH ? depth_mode_ : colour_mode_, camera_);
    std::lock_guard lock(streams_mutex_);
    streams_.push_back(stream);
    return stream.get();
  }

  void destroyStream(oni::driver::StreamBase* stream) override {
    std::lock_guard lock(streams_mutex_);
    std::erase_if(streams_, [stream](const auto& s) { return s.get() == stream; });
  }

  // Hardware registration exists only when the scene's colour is rendered from the depth
  // camera; otherwise colour comes from its own camera and the host must register it.
  OniBool isImageRegistrationModeSupported(OniImageRegistrationMode mode) override {
    return mode == kNoRegistration ||
           (mode == ONI_IMAGE_REGISTRATION_DEPTH_TO_COLOR && camera_.colourRegistered());
  }
  OniBool isPropertySupported(int id) override {
    return id == ONI_DEVICE_PROPERTY_IMAGE_REGISTRATION ? TRUE : FALSE;
  }
  OniStatus getProperty(int id, void* data, int* size) override {
    if (id != ONI_DEVICE_PROPERTY_IMAGE_REGISTRATION || *size < static_cast<int>(sizeof(int)))
      return ONI_STATUS_NOT_SUPPORTED;
    *static_cast<int*>(data) = registration_;
    *size = sizeof(int);
    return ONI_STATUS_OK;
  }
  OniStatus setProperty(int id, const void* data, int size) override {
    if (id != ONI_DEVICE_PROPERTY_IMAGE_REGISTRATION || size != sizeof(int))
      return ONI_STATUS_NOT_SUPPORTED;
    const auto mode = static_cast<OniImageRegistrationMode>(*static_cast<const int*>(data));
    if (!isImageRegistrationModeSupported(mode)) return ONI_STATUS_NOT_SUPPORTED;
    registration_ = mode;
    return ONI_STATUS_OK;
  }

 private:
  // Delivers the scene's frames at its rate to the started streams, until the device goes.
  void emit() {
    const auto period = std::chrono::duration<double>(1.0 / camera_.fps());
    auto due = std::chrono::steady_clock::now();
    while (!stop_) {
      std::this_thread::sleep_until(due);
      due += std::chrono::duration_cast<std::chrono::steady_clock::duration>(period);
      // Frames flow once every stream created has started, so that depth and colour begin
      // with the same frame.
      if (!allStarted()) continue;
      if (!started_) {
        // The first frame a period later, as a camera's: OpenNI2 finishes starting the
        // streams after the driver's start() returns and drops frames that come before.
        started_ = true;
        continue;
      }
      bool unplugged = false;
      const std::optional<int> index = camera_.nextFrame(unplugged);
      if (unplugged) {
        on_lost_(cookie_);
        return;
      }
      if (!index) return;
      const tessera::test::RenderedFrame& frame = camera_.frame(*index);
      const std::uint64_t timestamp_us = camera_.timestampUs(*index);
      std::lock_guard lock(streams_mutex_);
      for (const auto& stream : streams_) {
        if (!stream->started()) continue;
        if (stream->type() != ONI_SENSOR_DEPTH && !camera_.hasColour(*index)) continue;
        stream->deliver(stream->type() == ONI_SENSOR_DEPTH ? frame.depth_mm : frame.rgb, *index,
                        timestamp_us);
      }
    }
  }
  bool allStarted() {
    std::lock_guard lock(streams_mutex_);
    return !streams_.empty() && std::all_of(streams_.begin(), streams_.end(),
                                            [](const auto& s) { return s->started(); });
  }

  SceneCamera& camera_;
  LostCallback on_lost_;
  void* cookie_;
  OniVideoMode depth_mode_{};
  OniVideoMode colour_mode_{};
  OniSensorInfo sensors_[2]{};
  int registration_ = kNoRegistration;
  std::mutex streams_mutex_;
  std::vector<std::shared_ptr<SceneStream>> streams_;
  std::atomic<bool> stop_{false};
  bool started_ = false;  // emitter thread only
  std::thread emitter_;
};

class SceneDriver : public oni::driver::DriverBase {
 public:
  explicit SceneDriver(OniDriverServices* services) : DriverBase(services) {}

  OniStatus initialize(oni::driver::DeviceConnectedCallback connected,
                       oni::driver::DeviceDisconnectedCallback disconnected,
                       oni::driver::DeviceStateChangedCallback state_changed,
                       void* cookie) override {
    const OniStatus status = DriverBase::initialize(connected, disconnected, state_changed, cookie);
    if (status != ONI_STATUS_OK) return status;
    const auto settings = tessera::test::CameraSettings::fromEnvironment();
    if (!settings) return ONI_STATUS_OK;  // no scene: this driver offers no device
    try {
      camera_ = std::make_unique<SceneCamera>(*settings);
    } catch (const std::exception& e) {
      getServices().errorLoggerAppend("tessera test device: %s", e.what());
      return ONI_STATUS_OK;
    }
    std::memset(&info_, 0, sizeof(info_));
    std::strncpy(info_.uri, camera_->uri().c_str(), ONI_MAX_STR - 1);
    std::strncpy(info_.vendor, "tessera", ONI_MAX_STR - 1);
    std::strncpy(info_.name, "synthetic scene camera", ONI_MAX_STR - 1);
    deviceConnected(&info_);
    return ONI_STATUS_OK;
  }

  oni::driver::DeviceBase* deviceOpen(const char* uri, const char* /*mode*/) override {
    if (!camera_ || std::strcmp(uri, info_.uri) != 0 || !camera_->present()) return nullptr;
    camera_->renderIfNeeded();
    return new SceneDevice(*camera_, &SceneDriver::lost, this);
  }
  void deviceClose(oni::driver::DeviceBase* device) override { delete device; }

  void shutdown() override {
    if (replug_.joinable()) replug_.join();
  }

 private:
  // The device went away: OpenNI2 forgets it. If it comes back, it announces itself again, as
  // a USB hot-plug event makes a real driver do; only then can OpenNI2 open it again.
  static void lost(void* cookie) {
    auto* driver = static_cast<SceneDriver*>(cookie);
    driver->deviceDisconnected(&driver->info_);
    if (const auto back_at = driver->camera_->backAt()) {
      if (driver->replug_.joinable()) driver->replug_.join();
      driver->replug_ = std::thread([driver, at = *back_at] {
        std::this_thread::sleep_until(at);
        driver->deviceConnected(&driver->info_);
      });
    }
  }

  std::unique_ptr<SceneCamera> camera_;
  OniDeviceInfo info_{};
  std::thread replug_;
};

}  // namespace

ONI_EXPORT_DRIVER(SceneDriver)
