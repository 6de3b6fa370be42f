#include "tessera/drivers/ros1/ros_source.h"

#include <chrono>
#include <limits>
#include <mutex>
#include <set>

#include <fmt/format.h>
#include <ros/ros.h>
#include <spdlog/spdlog.h>

#include "tessera/core/clock.h"
#include "tessera/core/error.h"
#include "tessera/core/frame_pairing.h"
#include "tessera/drivers/ros1/compressed_image.h"
#include "tessera/drivers/ros1/ros_image.h"
#include "tessera/drivers/ros1/ros_node.h"

namespace tessera::drivers::ros1 {

namespace {

bool endsWith(const std::string& text, const std::string& suffix) {
  return text.size() >= suffix.size() &&
         text.compare(text.size() - suffix.size(), suffix.size(), suffix) == 0;
}

class RosSource : public core::FrameSource {
 public:
  explicit RosSource(const RosSourceOptions& options)
      : options_(options), label_("ros://" + options.master_uri) {
    ensureRosNode(options_.master_uri);
    inbox_.depth_capacity = options_.queue_frames;
    inbox_.colour_capacity = 16;
    ros::NodeHandle node;
    const auto hints = ros::TransportHints().tcpNoDelay();
    // A topic of image_transport's compressed transports carries CompressedImage.
    if (endsWith(options_.topics.depth, "/compressedDepth")) {
      depth_ = node.subscribe(options_.topics.depth, 2, &RosSource::onCompressedDepth, this, hints);
    } else {
      depth_ = node.subscribe(options_.topics.depth, 2, &RosSource::onDepth, this, hints);
    }
    if (endsWith(options_.topics.colour, "/compressed")) {
      colour_ =
          node.subscribe(options_.topics.colour, 4, &RosSource::onCompressedColour, this, hints);
    } else {
      colour_ = node.subscribe(options_.topics.colour, 4, &RosSource::onColour, this, hints);
    }
    if (!options_.intrinsics) {
      info_ = node.subscribe(options_.topics.depth_info, 1, &RosSource::onDepthInfo, this);
    }
    if (!options_.colour_camera) {
      colour_info_ = node.subscribe(options_.topics.colour_info, 1, &RosSource::onColourInfo, this);
    }
    spdlog::info("{}: subscribed to {} and {} (master {})", label_, options_.topics.depth,
                 options_.topics.colour, resolveMasterUri(options_.master_uri));
  }

  ~RosSource() override { unsubscribe(); }

  core::ReadResult read() override {
    if (ended_) return {};
    if (waiting_for_publisher_ || !started_) {
      if (!waitForPublisher()) {
        ended_ = true;
        core::ReadResult end;
        end.problem = fmt::format("{}: no depth image on {} for {:.0f} s; the stream ends", label_,
                                  options_.topics.depth, options_.reconnect_timeout_s);
        return end;
      }
    }
    return nextFrame();
  }

  std::string name() const override { return label_; }
  bool isLive() const override { return true; }

  core::LiveStats liveStats() const override { return inbox_.withCounts(stats_); }

  void stopStreaming() override {
    unsubscribe();
    ended_ = true;
    std::lock_guard lock(inbox_.mutex);
    inbox_.dropped += inbox_.depth.size();
    inbox_.depth.clear();
  }

 private:
  void unsubscribe() {
    depth_.shutdown();
    colour_.shutdown();
    info_.shutdown();
    colour_info_.shutdown();
  }

  bool stopRequested() const { return options_.stop != nullptr && options_.stop->load(); }

  void onDepth(const sensor_msgs::ImageConstPtr& message) {
    if (!readsDepthEncoding(message->encoding)) {
      unreadable(options_.topics.depth, message->encoding, "depth", "16UC1, mono16, 32FC1");
      return;
    }
    depthArrived(message->header, [&] { return depthFromImage(*message); });
  }

  void onCompressedDepth(const sensor_msgs::CompressedImageConstPtr& message) {
    depthArrived(message->header, [&] { return depthFromCompressed(*message); });
  }

  void onColour(const sensor_msgs::ImageConstPtr& message) {
    if (!readsColourEncoding(message->encoding)) {
      unreadable(options_.topics.colour, message->encoding, "colour", readableColourEncodings());
      return;
    }
    colourArrived(message->header, [&] { return colourFromImage(*message); });
  }

  void onCompressedColour(const sensor_msgs::CompressedImageConstPtr& message) {
    colourArrived(message->header, [&] { return colourFromCompressed(*message); });
  }

  // A depth image decoded by `decode` (which throws core::SourceError for a bad one) into the
  // inbox.
  template <typename Decode>
  void depthArrived(const std_msgs::Header& header, Decode decode) {
    core::CapturedImage captured;
    captured.arrival_ns = core::steadyNowNs();
    captured.stamp = static_cast<std::int64_t>(header.stamp.toNSec());
    captured.device_index = static_cast<int>(header.seq);
    try {
      captured.image = decode();
    } catch (const std::exception& e) {  // SourceError, or no memory for a corrupt size
      warnOnce(fmt::format("{}: {}: {}", label_, options_.topics.depth, e.what()));
      return;
    }
    std::lock_guard lock(inbox_.mutex);
    // Images the publisher sent that never arrived (its queue or ours overflowed), where it
    // numbers them.
    std::size_t missed = 0;
    if (last_seq_ && header.seq > *last_seq_ + 1 && header.seq - *last_seq_ < 1000) {
      missed = header.seq - *last_seq_ - 1;
    }
    last_seq_ = header.seq;
    inbox_.pushDepth(std::move(captured), missed);
  }

  template <typename Decode>
  void colourArrived(const std_msgs::Header& header, Decode decode) {
    core::CapturedImage captured;
    captured.arrival_ns = core::steadyNowNs();
    captured.stamp = static_cast<std::int64_t>(header.stamp.toNSec());
    try {
      captured.image = decode();
    } catch (const std::exception& e) {  // SourceError, or no memory for a corrupt size
      warnOnce(fmt::format("{}: {}: {}", label_, options_.topics.colour, e.what()));
      return;
    }
    std::lock_guard lock(inbox_.mutex);
    inbox_.pushColour(std::move(captured));
  }

  void onDepthInfo(const sensor_msgs::CameraInfoConstPtr& message) {
    std::lock_guard lock(inbox_.mutex);
    depth_info_ = intrinsicsFromCameraInfo(*message);
  }

  void onColourInfo(const sensor_msgs::CameraInfoConstPtr& message) {
    std::lock_guard lock(inbox_.mutex);
    colour_info_intrinsics_ = intrinsicsFromCameraInfo(*message);
  }

  // A topic in an encoding tessera does not read: the stream ends with one error.
  void unreadable(const std::string& topic, const std::string& encoding, const char* role,
                  const std::string& readable) {
    std::lock_guard lock(inbox_.mutex);
    if (!unreadable_.empty()) return;
    unreadable_ = fmt::format("{}: {} is in encoding '{}', which tessera does not read as {} ({})",
                              label_, topic, encoding, role, readable);
    inbox_.changed.notify_all();
  }

  void warnOnce(const std::string& problem) {
    std::lock_guard lock(warned_mutex_);
    if (warned_.insert(problem).second) spdlog::warn("{}", problem);
  }

  // After a stop: waits for the publisher's next depth image, or the end of the timeout.
  bool waitForPublisher() {
    if (started_) {
      spdlog::warn("{}: waiting up to {:.0f} s for images on {}", label_,
                   options_.reconnect_timeout_s, options_.topics.depth);
    } else {
      spdlog::info("{}: waiting up to {:.0f} s for the first image on {}", label_,
                   options_.reconnect_timeout_s, options_.topics.depth);
    }
    const auto deadline =
        std::chrono::steady_clock::now() +
        std::chrono::milliseconds(static_cast<std::int64_t>(options_.reconnect_timeout_s * 1000));
    std::unique_lock lock(inbox_.mutex);
    while (inbox_.depth.empty() && unreadable_.empty()) {
      if (stopRequested() || std::chrono::steady_clock::now() >= deadline) return false;
      inbox_.changed.wait_for(lock, std::chrono::milliseconds(100));
    }
    if (started_) {
      ++stats_.reconnects;
      spdlog::info("{}: images on {} again", label_, options_.topics.depth);
    }
    waiting_for_publisher_ = false;
    started_ = true;
    return true;
  }

  core::ReadResult nextFrame() {
    core::ReadResult result;
    std::unique_lock lock(inbox_.mutex);
    const auto give_up =
        std::chrono::steady_clock::now() + std::chrono::milliseconds(options_.frame_timeout_ms);
    while (!inbox_.changed.wait_for(lock, std::chrono::milliseconds(100), [&] {
      return !inbox_.depth.empty() || !unreadable_.empty();
    }) && std::chrono::steady_clock::now() < give_up) {
      if (stopRequested()) return result;  // the user ended the run
    }
    if (!unreadable_.empty()) {
      ended_ = true;
      result.problem = unreadable_;
      return result;
    }
    if (inbox_.depth.empty()) {
      ++stats_.device_losses;
      waiting_for_publisher_ = true;
      last_seq_.reset();  // a restarted publisher numbers from 0
      result.status = core::ReadStatus::kInterrupted;
      result.problem = fmt::format("{}: no depth image on {} for {} ms: the publisher stopped",
                                   label_, options_.topics.depth, options_.frame_timeout_ms);
      return result;
    }
    core::CapturedImage depth = std::move(inbox_.depth.front());
    inbox_.depth.pop_front();
    // The colour image nearest in stamp, waited for a little when it has not come yet.
    std::optional<core::CapturedImage> colour =
        inbox_.takeColourNear(lock, depth.stamp, options_.pair_tolerance_ns,
                              std::chrono::microseconds(options_.pair_tolerance_ns / 500));
    const std::optional<core::Intrinsics> info = depth_info_;
    const std::optional<core::Intrinsics> colour_info = colour_info_intrinsics_;
    lock.unlock();
    if (!colour) {
      result.status = core::ReadStatus::kBadFrame;
      result.problem = fmt::format("depth image at {:.6f} s has no colour image within {} ms",
                                   static_cast<double>(depth.stamp) * 1e-9,
                                   options_.pair_tolerance_ns / 1'000'000);
      return result;
    }
    core::Frame& frame = result.frame;
    if (options_.intrinsics) {
      frame.intrinsics = *options_.intrinsics;
    } else if (info && info->valid()) {
      frame.intrinsics = *info;
    } else {
      result.status = core::ReadStatus::kBadFrame;
      result.problem = fmt::format("no calibrated camera_info on {} yet; give --intrinsics",
                                   options_.topics.depth_info);
      return result;
    }
    frame.index = frames_out_++;
    frame.timestamp_ns = depth.stamp;
    frame.colour_timestamp_ns = colour->stamp;
    frame.arrival_ns = depth.arrival_ns;
    frame.depth_mm = std::move(depth.image);
    frame.rgb = std::move(colour->image);
    if (options_.colour_camera) {
      frame.colour_camera = options_.colour_camera;
    } else if (frame.rgb.size() != frame.depth_mm.size() && colour_info && colour_info->valid()) {
      frame.colour_camera = core::ColourCamera{*colour_info, core::Isometry::Identity()};
    } else if (frame.rgb.size() != frame.depth_mm.size()) {
      result.status = core::ReadStatus::kBadFrame;
      result.problem = fmt::format(
          "{}: colour {}x{} is not registered to depth {}x{}; give "
          "--calibration",
          label_, frame.rgb.cols, frame.rgb.rows, frame.depth_mm.cols, frame.depth_mm.rows);
      return result;
    }
    result.status = core::ReadStatus::kFrame;
    return result;
  }

  RosSourceOptions options_;
  std::string label_;
  ros::Subscriber depth_, colour_, info_, colour_info_;
  mutable core::PairingInbox inbox_;
  // Guarded by inbox_.mutex:
  std::optional<std::uint32_t> last_seq_;
  std::optional<core::Intrinsics> depth_info_, colour_info_intrinsics_;
  std::string unreadable_;  // set once: a topic in an encoding tessera does not read
  // The reader's own:
  core::LiveStats stats_;
  std::size_t frames_out_ = 0;
  bool started_ = false;  // the first depth image has come
  bool waiting_for_publisher_ = false;
  bool ended_ = false;
  std::mutex warned_mutex_;
  std::set<std::string> warned_;
};

}  // namespace

std::optional<std::string> parseRosUri(const std::string& source) {
  constexpr std::string_view kScheme = "ros://";
  if (source.rfind(kScheme, 0) != 0) return std::nullopt;
  return source.substr(kScheme.size());
}

std::unique_ptr<core::FrameSource> openRosSource(const RosSourceOptions& options) {
  return std::make_unique<RosSource>(options);
}

}  // namespace tessera::drivers::ros1
