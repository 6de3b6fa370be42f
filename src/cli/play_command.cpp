#include "play_command.h"

#include <chrono>
#include <deque>
#include <memory>
#include <thread>

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include "progress_line.h"
#include "stop_request.h"
#include "tessera/core/error.h"
#ifdef TESSERA_HAVE_ROS1
#include "tessera/drivers/ros1/compressed_image.h"
#include "tessera/drivers/ros1/ros_frame_publisher.h"
#endif

namespace tessera::cli {

CLI::App* addPlayCommand(CLI::App& app, PlayArguments& args) {
  CLI::App* play = app.add_subcommand(
      "play",
      "Publish SOURCE on a ROS 1 graph as a camera driver does (depth, colour, camera_info on "
      "the openni topics), at the pace it was recorded");
  play->add_option("SOURCE", args.source, "Recording, dataset folder, bag or synthetic scene")
      ->required();
  play->add_option("TARGET", args.target, "The graph: ros://[HOST:PORT] (default: ROS_MASTER_URI)")
      ->capture_default_str();
  play->add_option("--rate", args.rate, "Speed relative to the recording (2: twice as fast)")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  play->add_option("--skip", args.skip, "Leave out this many frames at the start")
      ->capture_default_str();
  play->add_option("--wait-for-subscriber", args.wait_for_subscriber_s,
                   "Seconds to wait for a subscriber to the depth topic before the first frame")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  play->add_flag("--preload", args.preload,
                 "Read and encode every frame into memory first, so that reading and encoding "
                 "take no CPU while publishing (a stand-in camera that costs what a driver on "
                 "its own machine costs)");
  play->add_option("--depth-encoding", args.depth_encoding, "16UC1 millimetres or 32FC1 metres")
      ->check(CLI::IsMember({"16UC1", "32FC1"}))
      ->capture_default_str();
  play->add_option("--colour-encoding", args.colour_encoding,
                   "rgb8, bgr8, bayer_rggb8, bayer_bggr8, bayer_gbrg8, bayer_grbg8, yuv422 or "
                   "yuv422_yuy2")
      ->check(CLI::IsMember({"rgb8", "bgr8", "bayer_rggb8", "bayer_bggr8", "bayer_gbrg8",
                             "bayer_grbg8", "yuv422", "yuv422_yuy2"}))
      ->capture_default_str();
  play->add_option("--compressed", args.compressed,
                   "Publish image_transport's compressed topics instead of raw images: depth on "
                   "DEPTH/compressedDepth (16-bit PNG), colour on COLOUR/compressed as png or "
                   "jpeg (quality 95)")
      ->check(CLI::IsMember({"png", "jpeg"}));
  addSourceOptions(*play, args.source_args);
  return play;
}

int playCommand(const PlayArguments& args) {
  try {
    constexpr std::string_view kScheme = "ros://";
    if (args.target.rfind(kScheme, 0) != 0) {
      throw core::ConfigError(fmt::format("{}: TARGET must be ros://[HOST:PORT]", args.target));
    }
#ifdef TESSERA_HAVE_ROS1
    auto source = openSource(args.source, args.source_args);
    drivers::ros1::RosFramePublisherOptions options;
    options.master_uri = args.target.substr(kScheme.size());
    if (!args.source_args.topic_set.empty()) {
      options.topics = *drivers::ros1::namedTopics(args.source_args.topic_set);
    }
    drivers::ros1::remapTopics(options.topics, args.source_args.topic_remaps);
    options.depth_encoding = args.depth_encoding;
    options.colour_encoding = args.colour_encoding;
    options.compressed = args.compressed;
    drivers::ros1::RosFramePublisher publisher(options);
    const std::atomic<bool>& stop = stopOnInterrupt();
    const auto wait_until =
        std::chrono::steady_clock::now() +
        std::chrono::milliseconds(static_cast<std::int64_t>(args.wait_for_subscriber_s * 1000));
    while (publisher.subscribers() == 0 && std::chrono::steady_clock::now() < wait_until && !stop) {
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    if (publisher.subscribers() == 0) {
      spdlog::warn("{}: nobody subscribes to {}; publishing anyway", args.target,
                   options.compressed.empty()
                       ? options.topics.depth
                       : drivers::ros1::compressedTopic(options.topics.depth, true));
    }
    // The frames to publish, in order: read as they are published, or all before.
    std::size_t read = 0;
    const auto next = [&]() -> std::optional<core::Frame> {
      for (;;) {
        core::ReadResult result = source->read();
        if (result.status == core::ReadStatus::kEndOfData) {
          if (!result.problem.empty()) spdlog::warn("{}", result.problem);
          return std::nullopt;
        }
        if (result.status == core::ReadStatus::kFrame && read++ >= args.skip) {
          return std::move(result.frame);
        }
      }
    };
    // Preloaded frames are encoded too (compressed images, the encodings): publishing them
    // then costs the sending alone, as a camera driver on its own machine would.
    struct Preloaded {
      std::int64_t timestamp_ns;
      std::shared_ptr<const drivers::ros1::RosFramePublisher::Encoded> messages;
    };
    std::deque<Preloaded> preloaded;
    if (args.preload) {
      const std::size_t limit = args.source_args.max_frames;
      while (limit == 0 || preloaded.size() < limit) {
        std::optional<core::Frame> frame = next();
        if (!frame) break;
        preloaded.push_back({frame->timestamp_ns, publisher.encode(*frame)});
      }
      spdlog::info("{}: {} frames read and encoded into memory", source->name(), preloaded.size());
    }
    ProgressLine progress;
    const auto start = std::chrono::steady_clock::now();
    std::optional<std::int64_t> first_stamp;
    std::size_t published = 0;
    while (!stop && (args.source_args.max_frames == 0 || published < args.source_args.max_frames)) {
      std::shared_ptr<const drivers::ros1::RosFramePublisher::Encoded> messages;
      std::int64_t timestamp_ns = 0;
      if (args.preload) {
        if (preloaded.empty()) break;
        timestamp_ns = preloaded.front().timestamp_ns;
        messages = std::move(preloaded.front().messages);
        preloaded.pop_front();
      } else {
        std::optional<core::Frame> frame = next();
        if (!frame) break;
        timestamp_ns = frame->timestamp_ns;
        messages = publisher.encode(*frame);
      }
      if (!first_stamp) first_stamp = timestamp_ns;
      // The recording's own pace: each frame leaves when its time since the first has passed.
      const auto due = start + std::chrono::nanoseconds(static_cast<std::int64_t>(
                                   static_cast<double>(timestamp_ns - *first_stamp) / args.rate));
      std::this_thread::sleep_until(due);
      publisher.publish(*messages, drivers::ros1::RosFramePublisher::now());
      ++published;
      const double elapsed =
          std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
      progress.update({published, source->frameCount(), elapsed, 0, std::nullopt});
    }
    progress.finish();
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    spdlog::info("published {} frames of {} on {} in {:.1f} s ({:.1f} frames/s)", published,
                 source->name(), args.target, seconds,
                 seconds > 0 ? static_cast<double>(published) / seconds : 0.0);
    return 0;
#else
    throw core::ConfigError(
        "tessera play: this tessera was built without ROS 1; install it with scripts/setup.sh "
        "and build again");
#endif
  } catch (const core::Error& e) {
    spdlog::error("{}", e.what());
    return 1;
  }
}

}  // namespace tessera::cli
