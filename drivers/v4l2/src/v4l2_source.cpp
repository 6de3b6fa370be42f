#include "tessera/drivers/v4l2/v4l2_source.h"

#include <chrono>
#include <cmath>

#include <fmt/format.h>
#include <spdlog/spdlog.h>
#include <opencv2/core.hpp>

#include "tessera/core/clock.h"
#include "tessera/core/error.h"
#include "tessera/drivers/v4l2/pixel_conversion.h"

namespace tessera::drivers::v4l2 {

namespace {

using Clock = std::chrono::steady_clock;

core::ReadResult badFrame(std::uint64_t index, std::string problem) {
  core::ReadResult result;
  result.status = core::ReadStatus::kBadFrame;
  result.problem = fmt::format("frame {}: {}", index, problem);
  return result;
}

}  // namespace

V4l2Source::V4l2Source(const std::string& uri, const V4l2Options& options)
    : uri_(uri), options_(options) {
  const V4l2Uri parsed = parseV4l2Uri(uri);
  std::optional<V4l2Profile> profile;
  if (!parsed.profile.empty()) profile = profileByName(parsed.profile);
  std::filesystem::path calibration_file = parsed.calibration;
  if (calibration_file.empty() && profile) calibration_file = profile->calibration;

  std::optional<CameraCalibration> calibration;
  if (!calibration_file.empty()) calibration = loadCameraCalibration(calibration_file);
  if (profile && calibration) {
    const auto& colour = calibration->colour;
    if (calibration->depth.width != profile->depth_width ||
        calibration->depth.height != profile->depth_height ||
        (colour && (colour->intrinsics.width != profile->colour_width ||
                    colour->intrinsics.height != profile->colour_height))) {
      throw core::ConfigError(fmt::format(
          "{}: the {} profile streams depth {}x{} and colour {}x{}; the calibration is for "
          "other sizes",
          calibration_file.string(), profile->name, profile->depth_width, profile->depth_height,
          profile->colour_width, profile->colour_height));
    }
  }
  std::string intrinsics_origin = calibration_file.string();
  if (calibration) intrinsics_ = calibration->depth;
  if (options.intrinsics) {
    const int width = intrinsics_.width, height = intrinsics_.height;
    intrinsics_ = *options.intrinsics;
    if (intrinsics_.width <= 0 || intrinsics_.height <= 0) {
      intrinsics_.width = width;
      intrinsics_.height = height;
    }
    intrinsics_origin = "--intrinsics";
  } else if (!calibration) {
    throw core::ConfigError(fmt::format(
        "{}: no depth intrinsics; pass --intrinsics, calibration=FILE.yaml or profile=kinect_v2",
        uri));
  }

  const DeviceFactory make_device = options.make_device
                                        ? options.make_device
                                        : [](const std::string&) { return makeSystemDevice(); };
  CaptureConfig depth_config;
  depth_config.path = parsed.depth_path;
  depth_config.role = "depth";
  depth_config.formats = depthFormatPreferences();
  depth_config.width = intrinsics_.width;  // 0: the node's current size
  depth_config.height = intrinsics_.height;
  depth_config.size_reason = fmt::format("the size of the intrinsics from {}", intrinsics_origin);
  depth_config.buffer_count = options.buffer_count;
  depth_config.stall_timeout_ms = options.stall_timeout_ms;
  depth_ = std::make_unique<V4l2Capture>(make_device(depth_config.path), depth_config);
  intrinsics_.width = depth_->format().width;
  intrinsics_.height = depth_->format().height;

  if (!parsed.colour_path.empty()) {
    CaptureConfig colour_config = depth_config;
    colour_config.path = parsed.colour_path;
    colour_config.role = "colour";
    colour_config.formats = colourFormatPreferences();
    if (calibration && calibration->colour) {
      colour_camera_ = calibration->colour;
      colour_config.width = colour_camera_->intrinsics.width;
      colour_config.height = colour_camera_->intrinsics.height;
      colour_config.size_reason = "the colour size in " + calibration_file.string();
    } else {
      colour_config.width = intrinsics_.width;
      colour_config.height = intrinsics_.height;
      colour_config.size_reason =
          "colour without a calibration file must be registered to depth, at its size (add "
          "calibration=FILE.yaml to the URI)";
    }
    colour_ = std::make_unique<V4l2Capture>(make_device(colour_config.path), colour_config);
  }
  mirror_ = calibration && calibration->mirror;
  spdlog::info("{}: depth intrinsics {} from {}{}", uri_, intrinsics_.describe(), intrinsics_origin,
               mirror_ ? "; un-mirroring the images" : "");
}

V4l2Source::~V4l2Source() = default;

core::ReadResult V4l2Source::endOfData(std::string problem) {
  ended_ = true;
  core::ReadResult result;
  result.problem = std::move(problem);
  return result;
}

bool V4l2Source::catchUpColour(std::int64_t timestamp_ns, std::string& end_problem) {
  const auto deadline = Clock::now() + std::chrono::milliseconds(options_.pair_wait_ms);
  while (colour_queue_.empty() || colour_queue_.back().timestamp_ns < timestamp_ns) {
    const auto left =
        std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now());
    if (left.count() < 0) break;
    CaptureResult colour = colour_->next(static_cast<int>(left.count()));
    switch (colour.status) {
      case CaptureStatus::kImage:
        colour_queue_.push_back(std::move(colour));
        break;
      case CaptureStatus::kBadImage:
        colour_problem_ = std::move(colour.problem);
        break;
      case CaptureStatus::kTimeout:
        break;
      case CaptureStatus::kEnd:
        end_problem = std::move(colour.problem);
        return false;
    }
  }
  return true;
}

std::optional<CaptureResult> V4l2Source::takeColourFor(std::int64_t timestamp_ns,
                                                       std::string& why_not) {
  const auto tolerance_ns =
      static_cast<std::int64_t>(std::llround(options_.pair_tolerance_ms * 1e6));
  // Depth timestamps only grow: colour older than the tolerance matches no later depth frame.
  while (!colour_queue_.empty() &&
         colour_queue_.front().timestamp_ns < timestamp_ns - tolerance_ns) {
    colour_queue_.pop_front();
  }
  std::size_t best = colour_queue_.size();
  std::int64_t best_gap = 0;
  for (std::size_t i = 0; i < colour_queue_.size(); ++i) {
    const std::int64_t gap = std::abs(colour_queue_[i].timestamp_ns - timestamp_ns);
    if (best == colour_queue_.size() || gap < best_gap) best = i, best_gap = gap;
  }
  if (best == colour_queue_.size() || best_gap > tolerance_ns) {
    why_not = fmt::format("no colour frame within {} ms of depth at {} ns",
                          options_.pair_tolerance_ms, timestamp_ns);
    if (best != colour_queue_.size()) {
      why_not += fmt::format(" (nearest {:.1f} ms away)", static_cast<double>(best_gap) * 1e-6);
    }
    if (!colour_problem_.empty())
      why_not += fmt::format("; last colour problem: {}", colour_problem_);
    return std::nullopt;
  }
  // Frames before the best one are farther from every later depth frame too.
  colour_queue_.erase(colour_queue_.begin(),
                      colour_queue_.begin() + static_cast<std::ptrdiff_t>(best));
  colour_problem_.clear();
  return colour_queue_.front();  // kept: it may be nearest to the next depth frame too
}

core::ReadResult V4l2Source::read() {
  if (ended_) return {};
  CaptureResult depth;
  do {
    depth = depth_->next(options_.stall_timeout_ms);
  } while (depth.status == CaptureStatus::kTimeout);
  if (depth.status == CaptureStatus::kEnd) return endOfData(std::move(depth.problem));
  const std::int64_t arrival_ns = core::steadyNowNs();
  const std::uint32_t skipped = last_depth_sequence_ && depth.sequence > *last_depth_sequence_
                                    ? depth.sequence - *last_depth_sequence_ - 1
                                    : 0;
  last_depth_sequence_ = depth.sequence;
  stats_.frames_dropped += skipped;
  stats_.frames_delivered += skipped + 1;
  const std::uint64_t index = frames_read_++;
  if (depth.status == CaptureStatus::kBadImage) return badFrame(index, std::move(depth.problem));

  std::string problem;
  cv::Mat depth_mm = depthToMillimetres(depth_->format(), depth.bytes, problem);
  if (depth_mm.empty()) return badFrame(index, depth_->path() + ": " + problem);
  cv::Mat rgb;
  if (colour_) {
    if (!catchUpColour(depth.timestamp_ns, problem)) return endOfData(std::move(problem));
    const std::optional<CaptureResult> colour = takeColourFor(depth.timestamp_ns, problem);
    if (!colour) return badFrame(index, std::move(problem));
    rgb = colourToRgb(colour_->format(), colour->bytes, problem);
    if (rgb.empty()) return badFrame(index, colour_->path() + ": " + problem);
  }
  if (mirror_) {
    cv::flip(depth_mm, depth_mm, 1);
    if (!rgb.empty()) cv::flip(rgb, rgb, 1);
  }

  core::ReadResult result;
  result.status = core::ReadStatus::kFrame;
  core::Frame& frame = result.frame;
  frame.index = index;
  frame.timestamp_ns = depth.timestamp_ns;
  frame.arrival_ns = arrival_ns;
  frame.depth_mm = std::move(depth_mm);
  frame.rgb = std::move(rgb);
  frame.intrinsics = intrinsics_;
  if (colour_) frame.colour_camera = colour_camera_;
  return result;
}

std::unique_ptr<core::FrameSource> openV4l2Source(const std::string& uri,
                                                  const V4l2Options& options) {
  return std::make_unique<V4l2Source>(uri, options);
}

}  // namespace tessera::drivers::v4l2
