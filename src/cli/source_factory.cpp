#include "source_factory.h"

#include <cstdlib>
#include <vector>

#include <fmt/format.h>

#include "stop_request.h"
#include "tessera/core/bouncing_source.h"
#include "tessera/core/error.h"
#include "tessera/drivers/dataset_source.h"
#include "tessera/drivers/freenect/freenect_source.h"
#include "tessera/drivers/oni/oni_source.h"
#include "tessera/drivers/openni2/openni2_source.h"
#include "tessera/drivers/synthetic/renderer.h"
#include "tessera/drivers/v4l2/camera_calibration.h"
#include "tessera/drivers/v4l2/v4l2_source.h"
#ifdef TESSERA_HAVE_ROS1
#include "tessera/drivers/ros1/bag_source.h"
#include "tessera/drivers/ros1/ros_source.h"
#endif

namespace tessera::cli {

namespace fs = std::filesystem;

namespace {
// The synthetic office (rendered by the build), else the committed real TUM frames.
constexpr const char* kDefaultRecordings[] = {"office.oni", "tum_fr1_rpy_20.oni"};
}  // namespace

namespace {

void addRosOptions(CLI::App& command, SourceArguments& args) {
  command
      .add_option(
          "--topics", args.topic_set,
          "ROS bags and ros://: the topic names of openni (openni2_launch and freenect_launch with "
          "depth registration) or tum (the TUM RGB-D bags); default: the first set the "
          "bag has")
      ->check(CLI::IsMember({"openni", "tum"}));
  command.add_option(
      "--topic", args.topic_remaps,
      "ROS bags and ros://: one topic named in ROS's remapping syntax ROLE:=TOPIC, ROLE one "
      "of depth, colour, depth_info, colour_info, pose (tf or PoseStamped ground "
      "truth); may be repeated. A depth topic ending in /compressedDepth or a colour topic "
      "ending in /compressed is read as image_transport's compressed transport");
  command
      .add_option("--world-frame", args.world_frame,
                  "ROS bags: the tf frame the ground-truth poses are given in")
      ->capture_default_str();
  command.add_option("--camera-frame", args.camera_frame,
                     "ROS bags: the tf frame whose pose is the camera's (default: the depth "
                     "images' frame_id)");
  command
      .add_option(
          "--pair-tolerance", args.pair_tolerance_ms,
          "ROS bags and ros://: milliseconds a colour image's stamp may be from its depth image's")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
}

std::unique_ptr<core::FrameSource> openBag(const std::string& spec, const SourceArguments& args,
                                           const std::optional<core::Intrinsics>& intrinsics) {
#ifdef TESSERA_HAVE_ROS1
  drivers::ros1::BagSourceOptions options;
  options.intrinsics = intrinsics;
  if (!args.topic_set.empty() || !args.topic_remaps.empty()) {
    options.topics = drivers::ros1::namedTopics(args.topic_set.empty() ? "openni" : args.topic_set);
    drivers::ros1::remapTopics(*options.topics, args.topic_remaps);
    for (const std::string& remap : args.topic_remaps) {
      options.pose_named = options.pose_named || remap.rfind("pose:=", 0) == 0;
    }
  }
  options.world_frame = args.world_frame;
  options.camera_frame = args.camera_frame;
  options.pair_tolerance_ns = static_cast<std::int64_t>(args.pair_tolerance_ms * 1e6);
  if (!args.calibration.empty()) {
    options.colour_camera = drivers::v4l2::loadCameraCalibration(args.calibration).colour;
  }
  return drivers::ros1::openBagSource(spec, options);
#else
  (void)args;
  (void)intrinsics;
  throw core::SourceError(fmt::format(
      "{}: this tessera was built without ROS 1; install it with scripts/setup.sh and build again "
      "to read bags",
      spec));
#endif
}

std::unique_ptr<core::FrameSource> openRos(const std::string& spec, const SourceArguments& args,
                                           const std::optional<core::Intrinsics>& intrinsics) {
#ifdef TESSERA_HAVE_ROS1
  drivers::ros1::RosSourceOptions options;
  options.master_uri = *drivers::ros1::parseRosUri(spec);
  if (!args.topic_set.empty()) options.topics = *drivers::ros1::namedTopics(args.topic_set);
  drivers::ros1::remapTopics(options.topics, args.topic_remaps);
  options.intrinsics = intrinsics;
  options.pair_tolerance_ns = static_cast<std::int64_t>(args.pair_tolerance_ms * 1e6);
  options.frame_timeout_ms = args.frame_timeout_ms;
  options.reconnect_timeout_s = args.reconnect_timeout_s;
  options.stop = &stopOnInterrupt();
  if (!args.calibration.empty()) {
    options.colour_camera = drivers::v4l2::loadCameraCalibration(args.calibration).colour;
  }
  if (!args.record_path.empty()) {
    throw core::ConfigError(
        "--record: a ROS source does not record itself; record its topics with rosbag record, "
        "which tessera replays");
  }
  return drivers::ros1::openRosSource(options);
#else
  (void)args;
  (void)intrinsics;
  throw core::SourceError(fmt::format(
      "{}: this tessera was built without ROS 1; install it with scripts/setup.sh and build again",
      spec));
#endif
}

}  // namespace

void addSourceOptions(CLI::App& command, SourceArguments& args) {
  command.add_option("--intrinsics", args.intrinsics,
                     "Camera intrinsics 'fx,fy,cx,cy[,width,height]' or a YAML file with those "
                     "keys; overrides what the source carries");
  command
      .add_option("--depth-scale", args.depth_units_per_m,
                  "Raw depth units per metre of a dataset folder (TUM 5000, millimetre "
                  "formats 1000); default: the layout's own")
      ->check(CLI::PositiveNumber);
  command.add_option("--max-frames", args.max_frames, "Stop after this many frames (0: all)")
      ->capture_default_str();
  command
      .add_option("--bounce", args.bounce,
                  "Recordings: play N passes, alternately forwards and backwards, so that a "
                  "short clip becomes a long stream whose camera path never jumps (the frames "
                  "are kept in memory, up to 2 GB)")
      ->check(CLI::Range(1, 1000))
      ->capture_default_str();
  command
      .add_option("--depth-mode", args.depth_mode,
                  "Live devices: depth stream mode WIDTHxHEIGHT@FPS (`tessera devices` lists them)")
      ->capture_default_str();
  command.add_option("--colour-mode", args.colour_mode, "Live devices: colour stream mode")
      ->capture_default_str();
  command
      .add_option("--reconnect-timeout", args.reconnect_timeout_s,
                  "Live devices: seconds to wait for an unplugged or stalled device to come back "
                  "before the run ends with the map exported")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  command
      .add_option("--calibration", args.calibration,
                  "Live OpenNI2 and libfreenect devices without hardware registration: YAML with "
                  "the depth and colour intrinsics and T_RGB_D (layout of config/kinect_v2.yaml); "
                  "tessera then registers colour to depth itself")
      ->check(CLI::ExistingFile);
  command
      .add_option("--frame-timeout", args.frame_timeout_ms,
                  "Live devices: milliseconds without a frame after which the stream counts as "
                  "stalled")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  addRosOptions(command, args);
}

namespace {

std::unique_ptr<core::FrameSource> openOnePass(const std::string& spec,
                                               const SourceArguments& args) {
  std::optional<core::Intrinsics> intrinsics;
  if (!args.intrinsics.empty()) intrinsics = core::parseIntrinsicsSpec(args.intrinsics);
  if (spec.rfind("ros://", 0) == 0) return openRos(spec, args, intrinsics);
  if (const auto uri = drivers::openni2::parseOpenNi2Uri(spec)) {
    drivers::openni2::OpenNi2Options options;
    options.uri = *uri;
    options.intrinsics = intrinsics;
    options.depth_mode = drivers::openni2::parseVideoMode(args.depth_mode);
    options.colour_mode = drivers::openni2::parseVideoMode(args.colour_mode);
    options.reconnect_timeout_s = args.reconnect_timeout_s;
    options.frame_timeout_ms = args.frame_timeout_ms;
    options.record_path = args.record_path;
    options.stop = &stopOnInterrupt();
    if (!args.calibration.empty()) {
      const auto calibration = drivers::v4l2::loadCameraCalibration(args.calibration);
      options.colour_camera = calibration.colour;
      if (!options.intrinsics) options.intrinsics = calibration.depth;
    }
    return std::make_unique<drivers::openni2::OpenNi2Source>(options);
  }
  if (drivers::freenect::parseFreenectUri(spec)) {
    drivers::freenect::FreenectOptions options;
    options.intrinsics = intrinsics;
    options.reconnect_timeout_s = args.reconnect_timeout_s;
    options.frame_timeout_ms = args.frame_timeout_ms;
    if (!args.calibration.empty()) {
      const auto calibration = drivers::v4l2::loadCameraCalibration(args.calibration);
      options.colour_camera = calibration.colour;
      if (!options.intrinsics) options.intrinsics = calibration.depth;
    }
    if (!args.record_path.empty()) {
      throw core::ConfigError(
          "--record: libfreenect devices do not record; open the Kinect through OpenNI2 "
          "(openni2://) to record it");
    }
    return drivers::freenect::openFreenectSource(spec, options);
  }
  if (drivers::v4l2::isV4l2Uri(spec)) {
    drivers::v4l2::V4l2Options options;
    options.intrinsics = intrinsics;
    options.stall_timeout_ms = args.frame_timeout_ms;
    if (!args.record_path.empty()) {
      throw core::ConfigError(
          "--record: V4L2 devices do not record yet; record an OpenNI2 device, or replay");
    }
    return drivers::v4l2::openV4l2Source(spec, options);
  }
  if (!args.record_path.empty()) {
    throw core::ConfigError(fmt::format(
        "--record: only live devices record while running; convert {} with `tessera record`",
        spec));
  }
  std::error_code ec;
  if (fs::is_directory(spec, ec)) {
    drivers::DatasetOptions options;
    options.intrinsics = intrinsics;
    if (args.depth_units_per_m > 0.0) options.depth_units_per_m = args.depth_units_per_m;
    return std::make_unique<drivers::DatasetSource>(spec, options);
  }
  if (fs::path(spec).extension() == ".bag") return openBag(spec, args, intrinsics);
  if (fs::path(spec).extension() == ".oni") {
    drivers::oni::OniSourceOptions options;
    options.intrinsics = intrinsics;
    return std::make_unique<drivers::oni::OniSource>(spec, options);
  }
  if (const auto ext = fs::path(spec).extension();
      (ext == ".yaml" || ext == ".yml") && fs::is_regular_file(spec, ec)) {
    return std::make_unique<drivers::synthetic::SyntheticSource>(spec);
  }
  if (fs::exists(spec, ec)) {
    throw core::SourceError(fmt::format(
        "{}: not a source tessera can read; SOURCE must be an OpenNI2 recording (.oni), a ROS 1 "
        "bag "
        "(.bag), a "
        "synthetic scene (.yaml), a recorded dataset folder (TUM RGB-D, 7-Scenes, Redwood or "
        "slambook layout), a live device (openni2://[URI], freenect://[N], v4l2://...) or a ROS "
        "graph (ros://[HOST:PORT])",
        spec));
  }
  throw core::SourceError(fmt::format("{}: no such file or folder", spec));
}

}  // namespace

std::unique_ptr<core::FrameSource> openSource(const std::string& spec,
                                              const SourceArguments& args) {
  std::unique_ptr<core::FrameSource> source = openOnePass(spec, args);
  if (args.bounce == 1) return source;
  return std::make_unique<core::BouncingSource>(std::move(source), args.bounce);
}

fs::path defaultRecording() {
  std::vector<fs::path> candidates;
  if (const char* env = std::getenv("TESSERA_RECORDINGS")) candidates.emplace_back(env);
  candidates.emplace_back("recordings");
  candidates.emplace_back(fs::path(TESSERA_SOURCE_DIR) / "recordings");
  for (const char* name : kDefaultRecordings) {
    for (const fs::path& dir : candidates) {
      std::error_code ec;
      if (fs::is_regular_file(dir / name, ec)) return dir / name;
    }
  }
  throw core::SourceError(
      fmt::format("no SOURCE given and no default recording (office.oni, rendered by the build, or "
                  "tum_fr1_rpy_20.oni) in $TESSERA_RECORDINGS, ./recordings or {}/recordings",
                  TESSERA_SOURCE_DIR));
}

}  // namespace tessera::cli
