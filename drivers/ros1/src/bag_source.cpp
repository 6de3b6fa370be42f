#include "tessera/drivers/ros1/bag_source.h"

#include <algorithm>
#include <deque>
#include <optional>

#include <fmt/format.h>
#include <geometry_msgs/PoseStamped.h>
#include <spdlog/spdlog.h>
#include <tf2_msgs/TFMessage.h>

#include "internal/bag_messages.h"
#include "internal/message_codec.h"
#include "internal/transform_tree.h"
#include "tessera/core/error.h"
#include "tessera/core/frame_pairing.h"
#include "tessera/drivers/ros1/compressed_image.h"
#include "tessera/drivers/ros1/ros_image.h"

namespace tessera::drivers::ros1 {

namespace {

constexpr const char* kImageType = "sensor_msgs/Image";
constexpr const char* kInfoType = "sensor_msgs/CameraInfo";
// A depth frame is paired once this many later depth frames are read: a recorder may store a
// colour image after the next depth images (about 130 ms late at 30 frames/s is allowed).
constexpr std::size_t kPairingLookahead = 4;

std::string describeTopics(const std::map<std::string, TopicSummary>& topics) {
  std::string text;
  for (const auto& [topic, summary] : topics) {
    text += fmt::format("\n  {} ({}, {} messages)", topic, summary.datatype, summary.messages);
  }
  return text.empty() ? " none" : text;
}

// Raw images or the compressed transports' (compressed_image.h).
bool hasImageTopic(const std::map<std::string, TopicSummary>& topics, const std::string& name) {
  const auto it = topics.find(name);
  return it != topics.end() &&
         (it->second.datatype == kImageType || it->second.datatype == kCompressedImageType);
}

// `raw` when the bag has it, else its compressed transport's topic when it has that.
std::optional<std::string> imageTopicIn(const std::map<std::string, TopicSummary>& topics,
                                        const std::string& raw, bool depth) {
  if (hasImageTopic(topics, raw)) return raw;
  if (hasImageTopic(topics, compressedTopic(raw, depth))) return compressedTopic(raw, depth);
  return std::nullopt;
}

class BagSource : public core::FrameSource {
 public:
  BagSource(std::filesystem::path path, const BagSourceOptions& options)
      : path_(std::move(path)), options_(options) {
    messages_ = openBagMessages(path_, salvage_note_);
    if (!salvage_note_.empty()) {
      spdlog::warn("{}: {}; playing what it holds", path_.string(), salvage_note_);
    }
    topics_ = chooseTopics();
    readCalibrationAndPoses();
    inbox_.colour_capacity = 64;
    messages_->select({topics_.depth, topics_.colour});
  }

  core::ReadResult read() override {
    for (;;) {
      if (auto result = pairFront()) return std::move(*result);
      if (at_end_) {
        core::ReadResult end;
        if (!unreadable_.empty()) {
          end.problem = unreadable_;
        } else if (!salvage_note_.empty()) {
          end.problem = fmt::format("{}: ended after {} frames: {}", path_.string(), frames_out_,
                                    salvage_note_);
        }
        return end;
      }
      std::optional<RawMessage> raw = messages_->next();
      if (!raw) {
        at_end_ = true;
        continue;
      }
      if (auto problem = take(*raw)) {
        core::ReadResult bad;
        bad.status = core::ReadStatus::kBadFrame;
        bad.problem = std::move(*problem);
        return bad;
      }
    }
  }

  std::string name() const override { return path_.string(); }
  std::optional<std::size_t> frameCount() const override {
    return messages_->topics().at(topics_.depth).messages;
  }

 private:
  RosTopics chooseTopics() const {
    const auto& topics = messages_->topics();
    if (options_.topics) {
      RosTopics chosen = *options_.topics;
      for (const std::string* name : {&chosen.depth, &chosen.colour}) {
        if (!hasImageTopic(topics, *name)) {
          throw core::SourceError(fmt::format("{}: no {} or {} topic {}; the bag has:{}",
                                              path_.string(), kImageType, kCompressedImageType,
                                              *name, describeTopics(topics)));
        }
      }
      if (!chosen.pose.empty() && !topics.count(chosen.pose)) {
        if (options_.pose_named) {
          throw core::SourceError(fmt::format("{}: no pose topic {}; the bag has:{}",
                                              path_.string(), chosen.pose, describeTopics(topics)));
        }
        chosen.pose.clear();
      }
      return chosen;
    }
    for (const RosTopics& known : {openniLaunchTopics(), tumTopics()}) {
      const auto depth = imageTopicIn(topics, known.depth, true);
      const auto colour = imageTopicIn(topics, known.colour, false);
      if (depth && colour) {
        RosTopics chosen = known;
        chosen.depth = *depth;
        chosen.colour = *colour;
        if (!topics.count(chosen.pose)) chosen.pose.clear();
        return chosen;
      }
    }
    throw core::SourceError(fmt::format(
        "{}: none of the known depth and colour topic sets ({}) is in the bag; name them with "
        "--topic depth:=TOPIC --topic colour:=TOPIC. The bag has:{}",
        path_.string(), knownTopicSetNames(), describeTopics(topics)));
  }

  // The first camera_info of each camera, and every ground-truth transform, before the images.
  void readCalibrationAndPoses() {
    std::set<std::string> wanted = {topics_.depth_info, topics_.colour_info, "/tf_static"};
    if (!topics_.pose.empty()) wanted.insert(topics_.pose);
    messages_->select(wanted);
    std::optional<core::Intrinsics> depth_info, colour_info;
    while (std::optional<RawMessage> raw = messages_->next()) {
      try {
        if (raw->datatype == kInfoType && raw->topic == topics_.depth_info && !depth_info) {
          depth_info = intrinsicsFromCameraInfo(decode<sensor_msgs::CameraInfo>(*raw));
        } else if (raw->datatype == kInfoType && raw->topic == topics_.colour_info &&
                   !colour_info) {
          colour_info = intrinsicsFromCameraInfo(decode<sensor_msgs::CameraInfo>(*raw));
        } else if (raw->topic == topics_.pose || raw->topic == "/tf_static") {
          addPoses(*raw, raw->topic == "/tf_static");
        }
      } catch (const core::SourceError& e) {
        spdlog::warn("{}: {}: {}", path_.string(), raw->topic, e.what());
      }
    }
    if (options_.intrinsics) {
      intrinsics_ = *options_.intrinsics;
    } else if (depth_info && depth_info->valid()) {
      intrinsics_ = *depth_info;
    } else {
      throw core::SourceError(
          fmt::format("{}: no calibrated camera_info on {}; give the depth camera's --intrinsics",
                      path_.string(), topics_.depth_info));
    }
    colour_camera_ = options_.colour_camera;
    if (!colour_camera_ && colour_info && colour_info->valid() &&
        (colour_info->width != intrinsics_.width || colour_info->height != intrinsics_.height)) {
      spdlog::warn(
          "{}: colour ({}x{}) is not registered to depth ({}x{}); without --calibration it is "
          "placed as if both cameras sat at the same point",
          path_.string(), colour_info->width, colour_info->height, intrinsics_.width,
          intrinsics_.height);
      colour_camera_ = core::ColourCamera{*colour_info, core::Isometry::Identity()};
    }
    if (!topics_.pose.empty() && poses_.empty()) {
      spdlog::warn("{}: {} holds no transforms; the frames have no ground truth", path_.string(),
                   topics_.pose);
    }
  }

  void addPoses(const RawMessage& raw, bool is_static) {
    if (raw.datatype == "tf2_msgs/TFMessage" || raw.datatype == "tf/tfMessage") {
      for (const auto& stamped : decode<tf2_msgs::TFMessage>(raw).transforms) {
        poses_.add(stamped.header.frame_id, stamped.child_frame_id,
                   static_cast<std::int64_t>(stamped.header.stamp.toNSec()),
                   isometryFromTransform(stamped.transform), is_static);
      }
    } else if (raw.datatype == "geometry_msgs/PoseStamped") {
      const auto pose = decode<geometry_msgs::PoseStamped>(raw);
      // The pose is the camera's own: it names the parent frame only.
      poses_.add(pose.header.frame_id, kPoseTopicCamera,
                 static_cast<std::int64_t>(pose.header.stamp.toNSec()), isometryFromPose(pose.pose),
                 false);
    } else {
      throw core::SourceError(fmt::format(
          "{} is not a pose topic tessera reads (tf2_msgs/TFMessage, geometry_msgs/PoseStamped)",
          raw.datatype));
    }
  }

  // Decodes a depth or colour message into the pairing queues; a problem for a bad one.
  std::optional<std::string> take(const RawMessage& raw) {
    try {
      const bool depth = raw.topic == topics_.depth;
      if (raw.datatype == kCompressedImageType) {
        const auto image = decode<sensor_msgs::CompressedImage>(raw);
        core::CapturedImage captured;
        captured.stamp = static_cast<std::int64_t>(image.header.stamp.toNSec());
        captured.image = depth ? depthFromCompressed(image) : colourFromCompressed(image);
        queue(std::move(captured), depth, image.header.frame_id);
        return std::nullopt;
      }
      const auto image = decode<sensor_msgs::Image>(raw);
      if (depth ? !readsDepthEncoding(image.encoding) : !readsColourEncoding(image.encoding)) {
        unreadable_ =
            fmt::format("{}: {} is in encoding '{}', which tessera does not read as {} ({})",
                        path_.string(), raw.topic, image.encoding, depth ? "depth" : "colour",
                        depth ? "16UC1, mono16, 32FC1" : readableColourEncodings());
        at_end_ = true;
        return std::nullopt;
      }
      core::CapturedImage captured;
      captured.stamp = static_cast<std::int64_t>(image.header.stamp.toNSec());
      captured.image = depth ? depthFromImage(image) : colourFromImage(image);
      queue(std::move(captured), depth, image.header.frame_id);
      return std::nullopt;
    } catch (const core::SourceError& e) {
      return fmt::format("{} message recorded at {:.3f} s: {}", raw.topic,
                         static_cast<double>(raw.record_ns) * 1e-9, e.what());
    }
  }

  void queue(core::CapturedImage captured, bool depth, const std::string& frame_id) {
    if (depth) {
      depth_frame_id_ = frame_id;
      pending_depth_.push_back(std::move(captured));
    } else {
      std::lock_guard lock(inbox_.mutex);  // the inbox's rule; this source has one thread
      inbox_.pushColour(std::move(captured));
    }
  }

  // The oldest depth frame with the colour image nearest in time, once any colour image for it
  // has had time to be read.
  std::optional<core::ReadResult> pairFront() {
    if (pending_depth_.empty()) return std::nullopt;
    const std::int64_t stamp = pending_depth_.front().stamp;
    if (!at_end_ && pending_depth_.size() <= kPairingLookahead) return std::nullopt;
    std::unique_lock lock(inbox_.mutex);
    std::optional<core::CapturedImage> colour = inbox_.takeColourNear(
        lock, stamp, options_.pair_tolerance_ns, std::chrono::microseconds(0));
    core::CapturedImage depth = std::move(pending_depth_.front());
    pending_depth_.pop_front();
    core::ReadResult result;
    if (!colour) {
      result.status = core::ReadStatus::kBadFrame;
      result.problem =
          fmt::format("depth image at {:.6f} s has no colour image within {} ms",
                      static_cast<double>(stamp) * 1e-9, options_.pair_tolerance_ns / 1'000'000);
      return result;
    }
    result.status = core::ReadStatus::kFrame;
    core::Frame& frame = result.frame;
    frame.index = frames_out_++;
    frame.timestamp_ns = stamp;
    frame.colour_timestamp_ns = colour->stamp;
    frame.depth_mm = std::move(depth.image);
    frame.rgb = std::move(colour->image);
    frame.intrinsics = intrinsics_;
    if (frame.intrinsics.width == 0) {
      frame.intrinsics.width = frame.depth_mm.cols;
      frame.intrinsics.height = frame.depth_mm.rows;
    }
    frame.colour_camera = colour_camera_;
    if (!frame.colour_camera && frame.rgb.size() != frame.depth_mm.size()) {
      result.status = core::ReadStatus::kBadFrame;
      result.problem = fmt::format(
          "colour {}x{} differs from depth {}x{} and no camera_info says how; give "
          "--calibration",
          frame.rgb.cols, frame.rgb.rows, frame.depth_mm.cols, frame.depth_mm.rows);
      return result;
    }
    if (!poses_.empty()) {
      const std::string camera = !poseTopicIsTf()                 ? kPoseTopicCamera
                                 : !options_.camera_frame.empty() ? options_.camera_frame
                                                                  : depth_frame_id_;
      frame.T_W_C_gt = poses_.lookup(options_.world_frame, camera, stamp);
    }
    return result;
  }

  bool poseTopicIsTf() const {
    const auto& topics = messages_->topics();
    const auto it = topics.find(topics_.pose);
    return it == topics.end() || it->second.datatype != "geometry_msgs/PoseStamped";
  }

  // The frame name a PoseStamped topic's poses are filed under.
  static constexpr const char* kPoseTopicCamera = "tessera/pose_topic";

  std::filesystem::path path_;
  BagSourceOptions options_;
  std::unique_ptr<BagMessages> messages_;
  std::string salvage_note_;
  std::string unreadable_;  // a topic in an encoding tessera does not read: the stream ends
  RosTopics topics_;
  core::Intrinsics intrinsics_;
  std::optional<core::ColourCamera> colour_camera_;
  TransformTree poses_;
  std::string depth_frame_id_;
  std::deque<core::CapturedImage> pending_depth_;
  core::PairingInbox inbox_;  // the colour images waiting to be paired
  std::size_t frames_out_ = 0;
  bool at_end_ = false;
};

}  // namespace

bool isBagPath(const std::filesystem::path& path) { return path.extension() == ".bag"; }

std::unique_ptr<core::FrameSource> openBagSource(const std::filesystem::path& path,
                                                 const BagSourceOptions& options) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) {
    throw core::SourceError(fmt::format("{}: no such file", path.string()));
  }
  return std::make_unique<BagSource>(path, options);
}

}  // namespace tessera::drivers::ros1
