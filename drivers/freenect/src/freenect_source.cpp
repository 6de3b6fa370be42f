#include "tessera/drivers/freenect/freenect_source.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <filesystem>
#include <thread>

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include "internal/fakenect_dump.h"
#include "internal/freenect_inbox.h"
#include "internal/freenect_runtime.h"
#include "tessera/core/error.h"
#include "tessera/drivers/freenect/kinect_v1.h"

namespace tessera::drivers::freenect {

namespace {

constexpr std::string_view kScheme = "freenect://";
constexpr int kLibusbInterrupted = -10;  // LIBUSB_ERROR_INTERRUPTED: a signal, not a failure
constexpr std::int64_t kPairingToleranceTicks = kFrameTicks / 2;
constexpr auto kFramePeriod = std::chrono::nanoseconds(1'000'000'000 / 30);

// 1e9 / 60 MHz = 50 / 3 ns per tick; the reduced fraction cannot overflow in centuries.
std::int64_t ticksToNs(std::int64_t ticks) { return ticks * 50 / 3; }

// One open device with libfreenect's event loop running on its own thread; closing it stops
// the loop first, then the streams, the device and the context.
struct Connection {
  Context context;
  freenect_device* device = nullptr;
  std::atomic<bool> stop{false};
  std::thread events;

  ~Connection() {
    stop = true;
    if (events.joinable()) events.join();
    if (device != nullptr) {
      freenect_stop_depth(device);
      freenect_stop_video(device);
      freenect_close_device(device);
    }
  }
};

void runEvents(Connection& connection, FrameInbox& inbox) {
  while (!connection.stop.load()) {
    timeval timeout{0, 100'000};
    const int status = freenect_process_events_timeout(connection.context.get(), &timeout);
    if (status < 0 && status != kLibusbInterrupted) {
      std::lock_guard lock(inbox.mutex);
      inbox.lost = true;
      inbox.loss_code = status;
      inbox.changed.notify_all();
      return;
    }
  }
}

class FreenectSource : public core::FrameSource {
 public:
  FreenectSource(int index, const FreenectOptions& options)
      : index_(index), options_(options), name_(fmt::format("{}{}", kScheme, index)) {
    label_ = name_;
    dump_ = fakenectDump(label_);
    if (dump_) {
      label_ += fmt::format(" (fakenect replay of {})", dump_->string());
      const std::size_t frames = checkFakenectDump(*dump_);
      spdlog::info("{}: {} depth frames to replay", label_, frames);
    }
    connect();
  }
  ~FreenectSource() override { connection_.reset(); }
  void stopStreaming() override {
    connection_.reset();
    ended_ = true;
    std::lock_guard lock(inbox_.mutex);
    inbox_.dropped += inbox_.depth.size();  // never to be read
    inbox_.depth.clear();
  }

  core::ReadResult read() override;
  std::string name() const override { return name_; }
  bool isLive() const override { return true; }
  core::LiveStats liveStats() const override { return inbox_.withCounts(stats_); }

 private:
  void connect();
  bool reconnect();
  core::ReadResult nextFrame();

  int index_;
  FreenectOptions options_;
  std::string name_;
  std::string label_;  // the name, and the dump folder when fakenect replays one
  std::optional<std::filesystem::path> dump_;
  mutable FrameInbox inbox_;  // declared before the connection, whose thread writes it
  std::unique_ptr<Connection> connection_;
  core::Intrinsics intrinsics_;
  std::optional<core::ColourCamera> colour_camera_;  // set when depth is not registered
  core::LiveStats stats_;
  std::uint64_t frames_out_ = 0;
  bool ended_ = false;
};

void FreenectSource::connect() {
  auto c = std::make_unique<Connection>();
  c->context = openContext(label_);
  const int count = freenect_num_devices(c->context.get());
  if (count <= 0) {
    throw core::SourceError(fmt::format(
        "{}: libfreenect finds no Kinect v1 (plugged in, powered, and may this user open it? "
        "see docs/FREENECT.md)",
        label_));
  }
  if (index_ >= count) {
    throw core::SourceError(
        fmt::format("{}: there is no device {}: libfreenect finds {} (use "
                    "freenect://0 to freenect://{})",
                    label_, index_, count, count - 1));
  }
  if (freenect_open_device(c->context.get(), &c->device, index_) < 0) {
    c->device = nullptr;
    throw core::SourceError(
        fmt::format("{}: cannot open the device (USB permissions? see docs/FREENECT.md)", label_));
  }
  const DepthMode depth = chooseDepthMode(label_);
  const freenect_frame_mode colour = chooseColourMode(label_);
  {
    std::lock_guard lock(inbox_.mutex);
    inbox_.clear();
    inbox_.depth_capacity = std::max<std::size_t>(1, options_.queue_frames);
    inbox_.depth_in_mm = depth.registered;
    inbox_.depth_bytes = static_cast<std::size_t>(depth.mode.bytes);
    inbox_.colour_bytes = static_cast<std::size_t>(colour.bytes);
  }
  freenect_set_user(c->device, &inbox_);
  freenect_set_depth_callback(c->device, onDepth);
  freenect_set_video_callback(c->device, onColour);
  if (freenect_set_depth_mode(c->device, depth.mode) < 0 ||
      freenect_set_video_mode(c->device, colour) < 0 || freenect_start_depth(c->device) < 0 ||
      freenect_start_video(c->device) < 0) {
    throw core::SourceError(fmt::format("{}: the depth and colour streams do not start", label_));
  }
  c->events = std::thread(runEvents, std::ref(*c), std::ref(inbox_));
  connection_ = std::move(c);

  intrinsics_ = options_.intrinsics.value_or(depth.registered ? typicalColourIntrinsics()
                                                              : typicalDepthIntrinsics());
  colour_camera_.reset();
  if (!depth.registered) colour_camera_ = options_.colour_camera.value_or(typicalColourCamera());
  spdlog::info("{}: depth {}, colour RGB 640x480, intrinsics {}", label_,
               depth.registered ? "registered to colour by libfreenect (mm)"
                                : "raw 11-bit disparity converted to mm, colour not registered",
               intrinsics_.describe());
}

bool FreenectSource::reconnect() {
  const auto start = std::chrono::steady_clock::now();
  const auto deadline = start + std::chrono::duration<double>(options_.reconnect_timeout_s);
  auto pause = std::chrono::duration<double>(0.1);
  spdlog::warn("{}: waiting up to {:.1f} s for the device to come back", label_,
               options_.reconnect_timeout_s);
  while (std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::min(
        pause, std::chrono::duration<double>(deadline - std::chrono::steady_clock::now())));
    pause = std::min(pause * 2.0, std::chrono::duration<double>(2.0));
    try {
      connect();
    } catch (const core::SourceError& e) {
      spdlog::debug("{}", e.what());
      continue;
    }
    // Opening is not enough (fakenect always opens): the device is back when it sends depth.
    const auto wait =
        std::min(std::chrono::duration<double>(options_.frame_timeout_ms / 1000.0),
                 std::chrono::duration<double>(deadline - std::chrono::steady_clock::now()));
    bool sending = false;
    {
      std::unique_lock lock(inbox_.mutex);
      inbox_.changed.wait_for(lock, wait, [&] { return !inbox_.depth.empty() || inbox_.lost; });
      sending = !inbox_.depth.empty();
    }
    if (sending) {
      ++stats_.reconnects;
      spdlog::info("{}: the device is back after {:.1f} s", label_,
                   std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
      return true;
    }
    connection_.reset();
  }
  return false;
}

core::ReadResult FreenectSource::nextFrame() {
  core::ReadResult result;
  std::unique_lock lock(inbox_.mutex);
  inbox_.changed.wait_for(lock, std::chrono::milliseconds(options_.frame_timeout_ms),
                          [&] { return !inbox_.depth.empty() || inbox_.lost; });
  if (inbox_.depth.empty()) {
    result.status = core::ReadStatus::kInterrupted;
    if (!inbox_.lost) {
      result.problem = fmt::format("{}: no depth frame for {} ms: the stream stalled", label_,
                                   options_.frame_timeout_ms);
    } else if (dump_) {
      result.problem = fmt::format("{}: the dump has no more frames", label_);
    } else {
      result.problem = fmt::format(
          "{}: libfreenect's event loop failed (error {}): the device "
          "was unplugged",
          label_, inbox_.loss_code);
    }
    return result;
  }
  core::CapturedImage depth = std::move(inbox_.depth.front());
  inbox_.depth.pop_front();
  // The colour frame nearest in time, waited for a little when it has not come yet.
  std::optional<core::CapturedImage> colour = inbox_.takeColourNear(
      lock, depth.stamp, kPairingToleranceTicks,
      inbox_.colourWait(std::chrono::duration_cast<std::chrono::microseconds>(2 * kFramePeriod)));
  if (!colour) {
    result.status = core::ReadStatus::kBadFrame;
    result.problem =
        fmt::format("{}: depth frame at {} ticks has no colour frame within {} ticks (60 MHz)",
                    label_, depth.stamp, kPairingToleranceTicks);
    return result;
  }
  core::Frame& frame = result.frame;
  frame.rgb = std::move(colour->image);
  frame.colour_timestamp_ns = ticksToNs(colour->stamp);  // its own time: no synchronisation
  lock.unlock();
  frame.index = frames_out_++;
  frame.timestamp_ns = ticksToNs(depth.stamp);
  frame.arrival_ns = depth.arrival_ns;
  frame.depth_mm = std::move(depth.image);
  frame.intrinsics = intrinsics_;
  frame.colour_camera = colour_camera_;
  result.status = core::ReadStatus::kFrame;
  return result;
}

core::ReadResult FreenectSource::read() {
  if (ended_) return {};
  if (!connection_ && !reconnect()) {
    ended_ = true;
    core::ReadResult end;
    end.problem = fmt::format("{}: the device did not come back within {:.1f} s", label_,
                              options_.reconnect_timeout_s);
    return end;
  }
  core::ReadResult result = nextFrame();
  if (result.status == core::ReadStatus::kInterrupted) {
    ++stats_.device_losses;
    connection_.reset();
  }
  return result;
}

}  // namespace

std::optional<int> parseFreenectUri(const std::string& uri) {
  if (uri.rfind(kScheme, 0) != 0) return std::nullopt;
  const std::string index = uri.substr(kScheme.size());
  if (index.empty()) return 0;
  if (index.size() > 3 ||
      !std::all_of(index.begin(), index.end(), [](char ch) { return ch >= '0' && ch <= '9'; })) {
    throw core::ConfigError(fmt::format(
        "'{}': expected freenect:// (the first Kinect v1) or freenect://N (device index N, "
        "from 0)",
        uri));
  }
  return std::stoi(index);
}

std::unique_ptr<core::FrameSource> openFreenectSource(const std::string& uri,
                                                      const FreenectOptions& options) {
  const std::optional<int> index = parseFreenectUri(uri);
  if (!index) {
    throw core::ConfigError(fmt::format("'{}' is not a freenect:// URI", uri));
  }
  return std::make_unique<FreenectSource>(*index, options);
}

}  // namespace tessera::drivers::freenect
