#include "tessera/drivers/oni/oni_source.h"

#include <cmath>
#include <cstring>
#include <deque>
#include <fstream>

#include <unistd.h>

#include <OpenNI.h>
#include <fmt/format.h>
#include <spdlog/spdlog.h>
#include <nlohmann/json.hpp>

#include "internal/oni_salvage.h"
#include "tessera/core/error.h"
#include "tessera/drivers/oni/ground_truth_file.h"
#include "tessera/drivers/oni/openni_runtime.h"

namespace tessera::drivers::oni {

namespace {

struct TimedFrame {
  std::int64_t timestamp_us = 0;
  cv::Mat image;
};

TimedFrame copyFrame(const openni::VideoFrameRef& ref, int type) {
  const cv::Mat view(ref.getHeight(), ref.getWidth(), type, const_cast<void*>(ref.getData()),
                     static_cast<std::size_t>(ref.getStrideInBytes()));
  return {static_cast<std::int64_t>(ref.getTimestamp()), view.clone()};
}

}  // namespace

std::filesystem::path groundTruthPath(const std::filesystem::path& oni) {
  std::filesystem::path sidecar = oni;
  sidecar.replace_extension(".gt.json");
  return sidecar;
}

struct OniSource::Device {
  openni::Device device;
  openni::VideoStream depth;
  openni::VideoStream colour;
  bool has_colour = false;
  int depth_frames = -1;  // from the file's stream header; -1 when unknown
  std::size_t depth_read = 0;
  int last_depth_index = 0;  // OpenNI frame numbers start at 1
  std::deque<TimedFrame> colour_queue;
  std::int64_t pair_tolerance_us = 16'667;  // half a frame period at 30 Hz
};

OniSource::OniSource(const std::filesystem::path& path, const OniSourceOptions& options)
    : path_(path), options_(options) {
  open();
}

void OniSource::rewind() {
  // OpenNI2's seek hangs or crashes inside the file driver: start again from a fresh device.
  closeDevice();
  poses_by_timestamp_us_.clear();
  colour_camera_.reset();
  frames_out_ = 0;
  ended_ = false;
  truncation_.clear();
  salvage_copy_.clear();
  open();
}

void OniSource::open() {
  const std::filesystem::path& path = path_;
  const OniSourceOptions& options = options_;
  device_ = std::make_unique<Device>();
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) {
    throw core::SourceError(fmt::format("{}: no such recording", path.string()));
  }
  ensureOpenNi();
  Device& d = *device_;
  if (d.device.open(path.c_str()) != openni::STATUS_OK) {
    const std::string openni_error = openni::OpenNI::getExtendedError();
    const internal::OniDiagnosis diagnosis = internal::diagnoseOni(path);
    if (!diagnosis.header_ok || diagnosis.complete || diagnosis.depth_frames == 0) {
      throw core::SourceError(
          fmt::format("{}: OpenNI2 cannot open the recording: {}", path.string(),
                      diagnosis.problem.empty() ? openni_error : diagnosis.problem));
    }
    // A cut file whose stream headers point past the cut: play a copy of its whole records.
    salvage_copy_ = std::filesystem::temp_directory_path() /
                    fmt::format("tessera-{}-{}", ::getpid(), path.filename().string());
    internal::writePlayableCopy(path, diagnosis, salvage_copy_);
    truncation_ = fmt::format("{}: the recording is {}", path.string(), diagnosis.problem);
    spdlog::warn("{}; playing the {} frames before the cut", truncation_, diagnosis.depth_frames);
    if (d.device.open(salvage_copy_.c_str()) != openni::STATUS_OK) {
      throw core::SourceError(fmt::format("{}: OpenNI2 cannot open the recording: {}",
                                          path.string(), diagnosis.problem));
    }
    d.depth_frames = static_cast<int>(diagnosis.depth_frames);
  }
  if (!d.device.hasSensor(openni::SENSOR_DEPTH) ||
      d.depth.create(d.device, openni::SENSOR_DEPTH) != openni::STATUS_OK) {
    throw core::SourceError(
        fmt::format("{}: the recording has no playable depth stream", path.string()));
  }
  d.has_colour = d.device.hasSensor(openni::SENSOR_COLOR) &&
                 d.colour.create(d.device, openni::SENSOR_COLOR) == openni::STATUS_OK;
  openni::PlaybackControl* playback = d.device.getPlaybackControl();
  if (playback == nullptr) {
    throw core::SourceError(
        fmt::format("{}: OpenNI2 opened it, but not as a recording", path.string()));
  }
  // Manual speed: each read releases exactly one frame, so none is skipped (speed 0 drops).
  playback->setSpeed(-1.0f);
  // Repeat stays on: with it off, OpenNI2's player closes the file at the end record on its
  // own thread, which raced with closing the device here (a crash in libOniFile). The source
  // stops at the file's frame count, or when frame numbers start again.
  playback->setRepeatEnabled(true);
  if (truncation_.empty()) d.depth_frames = playback->getNumberOfFrames(d.depth);
  const openni::VideoMode mode = d.depth.getVideoMode();
  if (mode.getPixelFormat() != openni::PIXEL_FORMAT_DEPTH_1_MM) {
    throw core::SourceError(fmt::format("{}: depth pixel format {} is not 1 mm depth",
                                        path.string(), static_cast<int>(mode.getPixelFormat())));
  }
  if (d.has_colour && d.colour.getVideoMode().getPixelFormat() != openni::PIXEL_FORMAT_RGB888) {
    spdlog::warn("{}: colour stream is not RGB888; playing depth only", path.string());
    d.colour.destroy();
    d.has_colour = false;
  }
  if (d.depth.start() != openni::STATUS_OK ||
      (d.has_colour && d.colour.start() != openni::STATUS_OK)) {
    throw core::SourceError(fmt::format("{}: OpenNI2 cannot start playback: {}", path.string(),
                                        openni::OpenNI::getExtendedError()));
  }

  // Intrinsics: --intrinsics, else the ground-truth sidecar, else the field of view.
  const auto sidecar = groundTruthPath(path);
  nlohmann::json gt;
  if (std::filesystem::exists(sidecar)) {
    std::ifstream in(sidecar);
    gt = nlohmann::json::parse(in, nullptr, /*allow_exceptions=*/false);
    if (gt.is_discarded()) {
      spdlog::warn("{}: not valid JSON; ignoring the ground truth", sidecar.string());
      gt = nlohmann::json();
    }
  }
  if (options.intrinsics) {
    intrinsics_ = *options.intrinsics;
    intrinsics_origin_ = "--intrinsics";
  } else if (gt.contains("intrinsics")) {
    intrinsics_ = intrinsicsFromJson(gt["intrinsics"]);
    intrinsics_origin_ = sidecar.string();
  } else {
    const double hfov = d.depth.getHorizontalFieldOfView(), vfov = d.depth.getVerticalFieldOfView();
    if (!(hfov > 0.0 && vfov > 0.0)) {
      throw core::ConfigError(
          fmt::format("{}: the recording has no field of view and no {}; pass --intrinsics",
                      path.string(), sidecar.filename().string()));
    }
    intrinsics_ = intrinsicsFromFov(mode.getResolutionX(), mode.getResolutionY(), hfov, vfov);
    intrinsics_origin_ = "the recording's field of view (principal point at the centre)";
  }
  intrinsics_.width = mode.getResolutionX();
  intrinsics_.height = mode.getResolutionY();
  if (gt.contains("colour_camera") && gt["colour_camera"].is_object()) {
    const auto& camera = gt["colour_camera"];
    const auto T_RGB_D = poseFromJson(camera.value("T_RGB_D", nlohmann::json()));
    if (T_RGB_D)
      colour_camera_ = core::ColourCamera{intrinsicsFromJson(camera["intrinsics"]), *T_RGB_D};
  }
  const nlohmann::json no_frames = nlohmann::json::array();
  for (const auto& frame : gt.is_object() ? gt.value("frames", no_frames) : no_frames) {
    const auto pose = poseFromJson(frame.value("T_W_C", nlohmann::json()));
    if (!pose || !frame.contains("timestamp_ns")) continue;
    poses_by_timestamp_us_[(frame["timestamp_ns"].get<std::int64_t>() + 500) / 1000] = *pose;
  }
  spdlog::info("{}: ONI recording, {} depth frames{}, {} with ground-truth pose", path.string(),
               d.depth_frames, d.has_colour ? " with colour" : " (no colour)",
               poses_by_timestamp_us_.size());
  spdlog::info("intrinsics {} from {}", intrinsics_.describe(), intrinsics_origin_);
}

OniSource::~OniSource() { closeDevice(); }

void OniSource::closeDevice() {
  if (!device_) return;
  device_->depth.stop();
  device_->depth.destroy();
  if (device_->has_colour) {
    device_->colour.stop();
    device_->colour.destroy();
  }
  device_->device.close();
  if (!salvage_copy_.empty()) {
    std::error_code ec;
    std::filesystem::remove(salvage_copy_, ec);
  }
  device_.reset();
}

bool OniSource::hasColour() const { return device_->has_colour; }

std::optional<std::size_t> OniSource::frameCount() const {
  if (device_->depth_frames <= 0) return std::nullopt;
  return static_cast<std::size_t>(device_->depth_frames);
}

std::string OniSource::truncationEnd() const {
  if (truncation_.empty()) return "";
  return fmt::format("{}; playback ends after frame {}", truncation_, frames_out_);
}

core::ReadResult OniSource::read() {
  core::ReadResult result;  // kEndOfData
  Device& d = *device_;
  if (ended_ || (d.depth_frames >= 0 && d.depth_read >= static_cast<std::size_t>(d.depth_frames))) {
    if (!ended_) result.problem = truncationEnd();
    ended_ = true;
    return result;
  }
  std::optional<TimedFrame> depth;
  std::optional<TimedFrame> colour;
  openni::VideoFrameRef ref;
  while (!depth || (d.has_colour && !colour)) {
    // Pair: the oldest queued colour frame within tolerance of the depth frame.
    if (depth && d.has_colour) {
      while (!d.colour_queue.empty() &&
             d.colour_queue.front().timestamp_us < depth->timestamp_us - d.pair_tolerance_us) {
        d.colour_queue.pop_front();  // older than any depth frame still to come
      }
      if (!d.colour_queue.empty()) {
        if (d.colour_queue.front().timestamp_us <= depth->timestamp_us + d.pair_tolerance_us) {
          colour = std::move(d.colour_queue.front());
          d.colour_queue.pop_front();
          break;
        }
        result.status = core::ReadStatus::kBadFrame;  // the colour stream skipped this time
        result.problem = fmt::format("frame {}: no colour frame within {} ms of depth at {} us",
                                     frames_out_, d.pair_tolerance_us / 1000, depth->timestamp_us);
        ++frames_out_;
        return result;
      }
    }
    openni::VideoStream* streams[2] = {&d.depth, &d.colour};
    int ready = -1;
    const auto status = openni::OpenNI::waitForAnyStream(streams, d.has_colour ? 2 : 1, &ready,
                                                         options_.frame_timeout_ms);
    if (status != openni::STATUS_OK || ready < 0) {
      ended_ = true;
      if (d.depth_frames < 0) return result;  // length unknown: a stall is the end
      result.problem = !truncation_.empty()
                           ? truncationEnd()
                           : fmt::format(
                                 "{}: the recording ends early after frame {} of {} "
                                 "(truncated or corrupt)",
                                 path_.string(), d.depth_read, d.depth_frames);
      return result;
    }
    if (streams[ready]->readFrame(&ref) != openni::STATUS_OK) continue;
    if (ready == 0) {
      if (ref.getFrameIndex() <= d.last_depth_index) {  // wrapped around: the recording ended
        ended_ = true;
        result.problem = truncationEnd();
        return result;
      }
      d.last_depth_index = ref.getFrameIndex();
      depth = copyFrame(ref, CV_16UC1);
      ++d.depth_read;
    } else {
      d.colour_queue.push_back(copyFrame(ref, CV_8UC3));
    }
  }

  core::Frame& frame = result.frame;
  frame.index = frames_out_++;
  frame.timestamp_ns = depth->timestamp_us * 1000;
  frame.depth_mm = std::move(depth->image);
  if (colour) {
    frame.rgb = std::move(colour->image);
    frame.colour_timestamp_ns = colour->timestamp_us * 1000;  // not synchronised with depth
  }
  frame.colour_camera = colour_camera_;
  frame.intrinsics = intrinsics_;
  if (const auto pose = poses_by_timestamp_us_.find(depth->timestamp_us);
      pose != poses_by_timestamp_us_.end()) {
    frame.T_W_C_gt = pose->second;
  }
  result.status = core::ReadStatus::kFrame;
  return result;
}

}  // namespace tessera::drivers::oni
