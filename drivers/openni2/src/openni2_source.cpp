#include "tessera/drivers/openni2/openni2_source.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <thread>

#include <OpenNI.h>
#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include "internal/frame_inbox.h"
#include "tessera/core/error.h"
#include "tessera/drivers/oni/ground_truth_file.h"
#include "tessera/drivers/oni/oni_source.h"
#include "tessera/drivers/oni/openni_runtime.h"
#include "tessera/drivers/openni2/device_list.h"

namespace tessera::drivers::openni2 {

namespace {

constexpr const char* kScheme = "openni2://";

std::string deviceLabel(const std::string& uri) {
  return std::string(kScheme) + (uri.empty() ? "(first device)" : uri);
}

// The offered mode of `request`'s size and rate in one of `formats`, in order of preference.
openni::VideoMode chooseMode(openni::Device& device, openni::SensorType type,
                             const VideoModeRequest& request,
                             std::initializer_list<openni::PixelFormat> formats,
                             const std::string& label, const char* sensor) {
  const openni::SensorInfo* info = device.getSensorInfo(type);
  if (info == nullptr) {
    throw core::SourceError(fmt::format("{}: the device has no {} sensor", label, sensor));
  }
  const openni::Array<openni::VideoMode>& offered = info->getSupportedVideoModes();
  for (openni::PixelFormat format : formats) {
    for (int i = 0; i < offered.getSize(); ++i) {
      const openni::VideoMode& m = offered[i];
      if (m.getResolutionX() == request.width && m.getResolutionY() == request.height &&
          m.getFps() == request.fps && m.getPixelFormat() == format)
        return m;
    }
  }
  std::string list;
  for (int i = 0; i < offered.getSize(); ++i) {
    list += fmt::format("{}{}x{}@{} {}", i == 0 ? "" : ", ", offered[i].getResolutionX(),
                        offered[i].getResolutionY(), offered[i].getFps(),
                        pixelFormatName(offered[i].getPixelFormat()));
  }
  throw core::SourceError(fmt::format("{}: {} mode {} is not offered; the device offers: {}", label,
                                      sensor, request.describe(), list));
}

std::filesystem::path segmentPath(const std::filesystem::path& path, int segment) {
  if (segment == 1) return path;
  std::filesystem::path numbered = path;
  numbered.replace_filename(
      fmt::format("{}-{}{}", path.stem().string(), segment, path.extension().string()));
  return numbered;
}

}  // namespace

std::string VideoModeRequest::describe() const {
  return fmt::format("{}x{}@{}", width, height, fps);
}

VideoModeRequest parseVideoMode(const std::string& text) {
  // WIDTHxHEIGHT@FPS, each a positive number (std::regex is avoided: GCC 12 warns inside it
  // under the sanitizer build).
  VideoModeRequest mode;
  char x = 0, at = 0;
  int consumed = 0;
  const bool parsed = std::sscanf(text.c_str(), "%5d%c%5d%c%4d%n", &mode.width, &x, &mode.height,
                                  &at, &mode.fps, &consumed) == 5 &&
                      x == 'x' && at == '@' && static_cast<std::size_t>(consumed) == text.size() &&
                      mode.width > 0 && mode.height > 0 && mode.fps > 0 &&
                      text.find_first_of("+- ") == std::string::npos;
  if (!parsed) {
    throw core::ConfigError(
        fmt::format("video mode '{}': expected WIDTHxHEIGHT@FPS, e.g. 640x480@30", text));
  }
  return mode;
}

std::optional<std::string> parseOpenNi2Uri(const std::string& source) {
  if (source.rfind(kScheme, 0) != 0) return std::nullopt;
  return source.substr(std::string(kScheme).size());
}

// One open device with its streams; closing it detaches everything in reverse order.
struct Connection {
  openni::Device device;
  openni::VideoStream depth;
  openni::VideoStream colour;
  std::unique_ptr<InboxListener> depth_listener;
  std::unique_ptr<InboxListener> colour_listener;
  openni::Recorder recorder;

  ~Connection() {
    if (recorder.isValid()) {
      recorder.stop();
      recorder.destroy();
    }
    if (depth_listener) depth.removeNewFrameListener(depth_listener.get());
    if (colour_listener) colour.removeNewFrameListener(colour_listener.get());
    depth.stop();
    colour.stop();
    depth.destroy();
    colour.destroy();
    device.close();
  }
};

struct OpenNi2Source::State {
  explicit State(const OpenNi2Options& o) : options(o), uri(o.uri), watch(inbox) {}

  void connect();
  void startRecording();
  bool reconnect();
  core::ReadResult nextFrame();

  OpenNi2Options options;
  std::string uri;  // resolved on the first open, so a reconnect finds the same device
  FrameInbox inbox;
  DisconnectWatch watch;
  std::unique_ptr<Connection> connection;
  core::Intrinsics intrinsics;
  bool hardware_registration = false;
  core::LiveStats stats;
  std::uint64_t frames_out = 0;
  int segment = 0;
  bool ended = false;
  bool session_start_pending = true;  // the next frame is a (re)connection's first
  // Added to the device's timestamps; moved on when a reconnected device restarts its clock.
  std::int64_t session_offset_us = 0;
  std::optional<std::int64_t> last_timestamp_us;

  bool stopRequested() const { return options.stop != nullptr && options.stop->load(); }
};

void OpenNi2Source::State::connect() {
  oni::ensureOpenNi();
  const std::string label = deviceLabel(uri);
  auto c = std::make_unique<Connection>();
  if (c->device.open(uri.empty() ? openni::ANY_DEVICE : uri.c_str()) != openni::STATUS_OK) {
    throw core::SourceError(
        fmt::format("{}: cannot open the device: {} (`tessera devices` lists "
                    "the devices OpenNI2 finds)",
                    label, openni::OpenNI::getExtendedError()));
  }
  uri = c->device.getDeviceInfo().getUri();
  watch.watch(uri);
  const openni::VideoMode depth_mode = chooseMode(
      c->device, openni::SENSOR_DEPTH, options.depth_mode,
      {openni::PIXEL_FORMAT_DEPTH_1_MM, openni::PIXEL_FORMAT_DEPTH_100_UM}, label, "depth");
  const openni::VideoMode colour_mode =
      chooseMode(c->device, openni::SENSOR_COLOR, options.colour_mode,
                 {openni::PIXEL_FORMAT_RGB888}, label, "colour");
  for (auto [stream, type, mode] : {std::tuple{&c->depth, openni::SENSOR_DEPTH, &depth_mode},
                                    std::tuple{&c->colour, openni::SENSOR_COLOR, &colour_mode}}) {
    if (stream->create(c->device, type) != openni::STATUS_OK ||
        stream->setVideoMode(*mode) != openni::STATUS_OK) {
      throw core::SourceError(fmt::format("{}: cannot set up the {} stream: {}", label,
                                          type == openni::SENSOR_DEPTH ? "depth" : "colour",
                                          openni::OpenNI::getExtendedError()));
    }
    // tessera's maps are in the camera's true geometry: a mirrored image would flip them.
    if (stream->setMirroringEnabled(false) != openni::STATUS_OK && stream->getMirroringEnabled()) {
      throw core::SourceError(fmt::format("{}: mirroring cannot be turned off", label));
    }
  }
  hardware_registration =
      !options.colour_camera &&
      c->device.isImageRegistrationModeSupported(openni::IMAGE_REGISTRATION_DEPTH_TO_COLOR) &&
      c->device.setImageRegistrationMode(openni::IMAGE_REGISTRATION_DEPTH_TO_COLOR) ==
          openni::STATUS_OK;
  // No depth/colour sync: frames are paired by time stamp below. OpenNI2 builds its synced
  // group from the streams already started when one starts, so with the two started one after
  // the other it held the depth stream alone; and each start and stop swaps the streams' frame
  // holders while their callbacks may be reading.

  if (options.intrinsics) {
    intrinsics = *options.intrinsics;
  } else if (const double hfov = c->depth.getHorizontalFieldOfView(),
             vfov = c->depth.getVerticalFieldOfView();
             hfov > 0.0 && vfov > 0.0) {
    intrinsics = oni::intrinsicsFromFov(depth_mode.getResolutionX(), depth_mode.getResolutionY(),
                                        hfov, vfov);
  } else {
    intrinsics = {};
  }
  if (!intrinsics.valid()) {
    throw core::SourceError(
        fmt::format("{}: the depth stream reports no field of view; pass --intrinsics", label));
  }
  {
    std::lock_guard lock(inbox.mutex);
    inbox.clear();
    inbox.depth_capacity = std::max<std::size_t>(1, options.queue_frames);
  }
  c->depth_listener = std::make_unique<InboxListener>(inbox, true);
  c->colour_listener = std::make_unique<InboxListener>(inbox, false);
  c->depth.addNewFrameListener(c->depth_listener.get());
  c->colour.addNewFrameListener(c->colour_listener.get());
  connection = std::move(c);
  session_start_pending = true;
  if (!options.record_path.empty()) {
    try {
      startRecording();
    } catch (...) {
      connection.reset();  // no half-set-up device: the next attempt starts clean
      throw;
    }
  }
  if (connection->depth.start() != openni::STATUS_OK ||
      connection->colour.start() != openni::STATUS_OK) {
    connection.reset();
    throw core::SourceError(
        fmt::format("{}: the streams do not start: {}", label, openni::OpenNI::getExtendedError()));
  }
  spdlog::info(
      "{}: depth {} and colour {}, {} registration, intrinsics {}", deviceLabel(uri),
      options.depth_mode.describe(), options.colour_mode.describe(),
      hardware_registration ? "hardware" : (options.colour_camera ? "host (--calibration)" : "no"),
      intrinsics.describe());
  if (!hardware_registration && !options.colour_camera) {
    spdlog::warn(
        "{}: the device cannot register colour to depth and no --calibration was "
        "given: colour is used as if registered",
        deviceLabel(uri));
  }
}

void OpenNi2Source::State::startRecording() {
  const std::filesystem::path path = segmentPath(options.record_path, ++segment);
  Connection& c = *connection;
  if (c.recorder.create(path.c_str()) != openni::STATUS_OK ||
      c.recorder.attach(c.depth, /*allowLossyCompression=*/false) != openni::STATUS_OK ||
      c.recorder.attach(c.colour, false) != openni::STATUS_OK ||
      c.recorder.start() != openni::STATUS_OK) {
    throw core::SourceError(
        fmt::format("{}: cannot record: {}", path.string(), openni::OpenNI::getExtendedError()));
  }
  // OpenNI2's Recorder starts on its own thread and ignores frames until it has: give it a
  // moment before the streams start, or it may miss their first frame (seen under load).
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  // The replay must use the intrinsics this run uses, not a guess from the field of view.
  oni::GroundTruthFile sidecar;
  sidecar.setIntrinsics(intrinsics);
  if (!hardware_registration && options.colour_camera)
    sidecar.setColourCamera(*options.colour_camera);
  sidecar.extra()["recorded_from"] = deviceLabel(uri);
  sidecar.write(oni::groundTruthPath(path));
  spdlog::info("recording {} to {}", deviceLabel(uri), path.string());
}

bool OpenNi2Source::State::reconnect() {
  const std::string label = deviceLabel(uri);
  const auto start = std::chrono::steady_clock::now();
  const auto deadline = start + std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                                    std::chrono::duration<double>(options.reconnect_timeout_s));
  auto pause = std::chrono::duration<double>(0.1);
  spdlog::warn("{}: waiting up to {:.0f} s for the device to come back", label,
               options.reconnect_timeout_s);
  while (std::chrono::steady_clock::now() < deadline && !stopRequested()) {
    // Sleep in short steps so that Ctrl-C is not kept waiting by the backoff.
    const auto wake = std::min<std::chrono::steady_clock::time_point>(
        std::chrono::steady_clock::now() +
            std::chrono::duration_cast<std::chrono::steady_clock::duration>(pause),
        deadline);
    while (std::chrono::steady_clock::now() < wake && !stopRequested()) {
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    pause = std::min(pause * 2.0, std::chrono::duration<double>(2.0));
    if (stopRequested()) break;
    try {
      connect();
      ++stats.reconnects;
      spdlog::info("{}: the device is back after {:.1f} s", label,
                   std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
      return true;
    } catch (const core::Error& e) {  // SourceError, or a recording sidecar that cannot be written
      spdlog::debug("{}", e.what());
    }
  }
  return false;
}

core::ReadResult OpenNi2Source::State::nextFrame() {
  core::ReadResult result;
  const auto period_us = static_cast<std::int64_t>(1e6 / std::max(1, options.depth_mode.fps));
  const std::int64_t tolerance_us = period_us / 2;
  std::unique_lock lock(inbox.mutex);
  const auto give_up =
      std::chrono::steady_clock::now() + std::chrono::milliseconds(options.frame_timeout_ms);
  // Waits in short steps so that Ctrl-C ends a run whose device has gone quiet.
  while (!inbox.changed.wait_for(lock, std::chrono::milliseconds(100), [&] {
    return !inbox.depth.empty() || inbox.lost;
  }) && std::chrono::steady_clock::now() < give_up) {
    if (stopRequested()) return result;  // end of data, no problem: the user stopped the run
  }
  if (inbox.depth.empty()) {
    result.status = core::ReadStatus::kInterrupted;
    result.problem = inbox.lost ? fmt::format("{}: the device was unplugged", deviceLabel(uri))
                                : fmt::format("{}: no depth frame for {} ms: the stream stalled",
                                              deviceLabel(uri), options.frame_timeout_ms);
    return result;
  }
  core::CapturedImage depth = std::move(inbox.depth.front());
  inbox.depth.pop_front();
  // The colour frame nearest in time, waited for a little when it has not come yet.
  std::optional<core::CapturedImage> colour = inbox.takeColourNear(
      lock, depth.stamp, tolerance_us, inbox.colourWait(std::chrono::microseconds(2 * period_us)));
  if (!colour) {
    result.status = core::ReadStatus::kBadFrame;
    result.problem = fmt::format("depth frame {} (t = {} us): no colour frame within {} us",
                                 depth.device_index, depth.stamp, tolerance_us);
    return result;
  }
  core::Frame& frame = result.frame;
  frame.rgb = std::move(colour->image);
  const std::int64_t colour_stamp = colour->stamp;
  lock.unlock();
  frame.index = frames_out++;
  // A reconnected device may restart its clock: later sessions continue after the last
  // timestamp, so that the trajectory and the stats stay in order.
  if (session_start_pending && last_timestamp_us &&
      depth.stamp + session_offset_us <= *last_timestamp_us) {
    session_offset_us = *last_timestamp_us + period_us - depth.stamp;
  }
  session_start_pending = false;
  last_timestamp_us = depth.stamp + session_offset_us;
  frame.timestamp_ns = *last_timestamp_us * 1000;
  // The two streams are not synchronised: the colour image has its own time (same clock).
  frame.colour_timestamp_ns = (colour_stamp + session_offset_us) * 1000;
  frame.arrival_ns = depth.arrival_ns;
  frame.depth_mm = std::move(depth.image);
  frame.intrinsics = intrinsics;
  if (!hardware_registration && options.colour_camera) frame.colour_camera = options.colour_camera;
  result.status = core::ReadStatus::kFrame;
  return result;
}

OpenNi2Source::OpenNi2Source(const OpenNi2Options& options)
    : state_(std::make_unique<State>(options)) {
  oni::ensureOpenNi();
  openni::OpenNI::addDeviceDisconnectedListener(&state_->watch);
  try {
    state_->connect();
  } catch (...) {
    openni::OpenNI::removeDeviceDisconnectedListener(&state_->watch);
    throw;
  }
}

OpenNi2Source::~OpenNi2Source() {
  state_->connection.reset();
  openni::OpenNI::removeDeviceDisconnectedListener(&state_->watch);
}

std::string OpenNi2Source::name() const { return deviceLabel(state_->uri); }
const core::Intrinsics& OpenNi2Source::intrinsics() const { return state_->intrinsics; }
bool OpenNi2Source::hardwareRegistration() const { return state_->hardware_registration; }

core::LiveStats OpenNi2Source::liveStats() const { return state_->inbox.withCounts(state_->stats); }

void OpenNi2Source::stopStreaming() {
  State& s = *state_;
  s.connection.reset();  // streams stop, the recording closes
  s.ended = true;
  std::lock_guard lock(s.inbox.mutex);
  s.inbox.dropped += s.inbox.depth.size();  // never to be read
  s.inbox.depth.clear();
}

core::ReadResult OpenNi2Source::read() {
  State& s = *state_;
  if (s.ended) return {};
  if (!s.connection) {
    if (!s.reconnect()) {
      s.ended = true;
      core::ReadResult end;
      end.problem = fmt::format("the device did not come back within {:.0f} s",
                                s.options.reconnect_timeout_s);
      return end;
    }
  }
  core::ReadResult result = s.nextFrame();
  if (result.status == core::ReadStatus::kInterrupted) {
    ++s.stats.device_losses;
    s.connection.reset();  // also ends this recording segment
  }
  return result;
}

}  // namespace tessera::drivers::openni2
