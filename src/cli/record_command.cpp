#include "record_command.h"

#include <chrono>

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include "progress_line.h"
#include "stop_request.h"
#include "tessera/core/error.h"
#include "tessera/drivers/oni/ground_truth_file.h"
#include "tessera/drivers/oni/oni_source.h"
#include "tessera/drivers/oni/oni_writer.h"
#include "tessera/drivers/openni2/openni2_source.h"
#include "tessera/drivers/synthetic/renderer.h"
#include "tessera/drivers/synthetic/scene_ground_truth.h"
#ifdef TESSERA_HAVE_ROS1
#include "tessera/drivers/ros1/bag_writer.h"
#endif

namespace tessera::cli {

namespace {

void addCodecOptions(CLI::App* record, RecordArguments& args) {
  record
      ->add_option("--depth-codec", args.depth_codec,
                   "16zT (OpenNI's lossless depth codec) or none (raw 16-bit)")
      ->check(CLI::IsMember({"16zT", "none"}))
      ->capture_default_str();
  record->add_option("--colour-codec", args.colour_codec, "jpeg (lossy) or none (raw RGB)")
      ->check(CLI::IsMember({"jpeg", "none"}))
      ->capture_default_str();
  record->add_option("--jpeg-quality", args.jpeg_quality, "JPEG quality, 1-100")
      ->check(CLI::Range(1, 100))
      ->capture_default_str();
}

struct CopyResult {
  std::size_t frames = 0;  // written
  std::size_t bad = 0;     // skipped
  std::string end_problem;
  double seconds = 0.0;
};

// Reads `source` to its end (or --max-frames), handing every good frame to `write`, with a
// progress line.
template <typename Write>
CopyResult copyFrames(core::FrameSource& source, std::size_t max_frames, Write write) {
  CopyResult copied;
  ProgressLine progress;
  const auto start = std::chrono::steady_clock::now();
  const auto elapsed = [&] {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  };
  while (max_frames == 0 || copied.frames < max_frames) {
    core::ReadResult result = source.read();
    if (result.status == core::ReadStatus::kEndOfData) {
      copied.end_problem = result.problem;
      break;
    }
    if (result.status == core::ReadStatus::kBadFrame) {
      ++copied.bad;
      spdlog::warn("{}: skipped {}", source.name(), result.problem);
      continue;
    }
    write(result.frame);
    ++copied.frames;
    progress.update({copied.frames, source.frameCount(), elapsed(), 0, std::nullopt});
  }
  progress.finish();
  copied.seconds = elapsed();
  if (copied.frames == 0) throw core::SourceError(source.name() + ": no frame could be read");
  if (!copied.end_problem.empty()) spdlog::error("{}", copied.end_problem);
  return copied;
}

void logSpeed(const CopyResult& copied) {
  spdlog::info("{:.1f} s, {:.1f} frames/s", copied.seconds,
               static_cast<double>(copied.frames) / copied.seconds);
}

// Writes every good frame of `source` to args.output and the sidecar (with `extra` keys).
int recordFrames(core::FrameSource& source, const RecordArguments& args,
                 const nlohmann::json& extra) {
  drivers::oni::OniWriterOptions options;
  options.depth_codec = args.depth_codec == "none" ? drivers::oni::DepthCodec::kNone
                                                   : drivers::oni::DepthCodec::k16zT;
  options.colour_codec = args.colour_codec == "none" ? drivers::oni::ColourCodec::kNone
                                                     : drivers::oni::ColourCodec::kJpeg;
  options.jpeg_quality = args.jpeg_quality;

  std::unique_ptr<drivers::oni::OniWriter> writer;  // opened at the first frame (its size)
  drivers::oni::GroundTruthFile ground_truth;
  const CopyResult copied =
      copyFrames(source, args.source_args.max_frames, [&](const core::Frame& frame) {
        if (!writer) {
          options.with_colour = !frame.rgb.empty();
          writer = std::make_unique<drivers::oni::OniWriter>(args.output, frame.intrinsics,
                                                             frame.rgb.size(), options);
          ground_truth.setIntrinsics(frame.intrinsics);
          if (frame.colour_camera) ground_truth.setColourCamera(*frame.colour_camera);
        }
        writer->write(frame);
        ground_truth.addFrame(frame);
      });
  writer->close();
  for (const auto& [key, value] : extra.items()) ground_truth.extra()[key] = value;
  const auto sidecar = drivers::oni::groundTruthPath(args.output);
  ground_truth.write(sidecar);
  spdlog::info(
      "wrote {} frames ({} bad skipped, {} with ground-truth pose) to {} ({:.1f} MB) and {}",
      writer->framesWritten(), copied.bad, ground_truth.framesWithPose(), args.output,
      static_cast<double>(std::filesystem::file_size(args.output)) / 1e6, sidecar.string());
  logSpeed(copied);
  return 0;
}

// Writes every good frame of `source` to the ROS 1 bag args.output, ground truth on /tf.
int recordBag(core::FrameSource& source, const RecordArguments& args) {
#ifdef TESSERA_HAVE_ROS1
  drivers::ros1::BagWriterOptions options;
  if (!args.source_args.topic_set.empty()) {
    options.topics = *drivers::ros1::namedTopics(args.source_args.topic_set);
  }
  drivers::ros1::remapTopics(options.topics, args.source_args.topic_remaps);
  options.depth_encoding = args.depth_encoding;
  options.colour_encoding = args.colour_encoding;
  options.world_frame = args.source_args.world_frame;
  if (!args.source_args.camera_frame.empty()) options.depth_frame = args.source_args.camera_frame;
  options.lz4 = args.bag_lz4;
  options.compressed = args.bag_compressed;
  drivers::ros1::BagWriter writer(args.output, options);
  std::size_t with_pose = 0;
  const CopyResult copied =
      copyFrames(source, args.source_args.max_frames, [&](const core::Frame& frame) {
        writer.write(frame);
        if (frame.T_W_C_gt) ++with_pose;
      });
  writer.close();
  spdlog::info("wrote {} frames ({} bad skipped, {} with ground truth on {}) to {} ({:.1f} MB)",
               writer.framesWritten(), copied.bad, with_pose,
               options.topics.pose.empty() ? "no topic" : options.topics.pose, args.output,
               static_cast<double>(std::filesystem::file_size(args.output)) / 1e6);
  logSpeed(copied);
  return 0;
#else
  (void)source;
  throw core::ConfigError(fmt::format(
      "{}: this tessera was built without ROS 1; install it with scripts/setup.sh and build "
      "again to write bags",
      args.output));
#endif
}

bool isBagOutput(const RecordArguments& args) {
  return std::filesystem::path(args.output).extension() == ".bag";
}

// A live device records itself through OpenNI2's Recorder while this reads it, until
// --max-frames, Ctrl-C, or the device is gone for good.
int recordLive(const RecordArguments& args) {
  SourceArguments source_args = args.source_args;
  source_args.record_path = args.output;
  auto source = openSource(args.source, source_args);
  const std::atomic<bool>& stop = stopOnInterrupt();
  ProgressLine progress;
  const auto start = std::chrono::steady_clock::now();
  std::size_t frames = 0;
  std::string end_problem;
  spdlog::info("recording {} to {}; Ctrl-C stops", source->name(), args.output);
  while (!stop && (args.source_args.max_frames == 0 || frames < args.source_args.max_frames)) {
    core::ReadResult result = source->read();
    if (result.status == core::ReadStatus::kEndOfData) {
      end_problem = result.problem;
      break;
    }
    if (result.status == core::ReadStatus::kFrame) ++frames;
    if (!result.problem.empty()) spdlog::warn("{}", result.problem);
    const double elapsed =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    progress.update({frames, std::nullopt, elapsed, 0, std::nullopt});
  }
  progress.finish();
  source->stopStreaming();  // closes the recording
  const core::LiveStats live = source->liveStats();
  if (!end_problem.empty()) spdlog::warn("{}", end_problem);
  spdlog::info(
      "{} frames sent by the device, all recorded to {}{}", live.frames_delivered, args.output,
      live.reconnects > 0 ? fmt::format(" and {} more segments after reconnects", live.reconnects)
                          : "");
  return 0;
}

}  // namespace

CLI::App* addRecordCommand(CLI::App& app, RecordArguments& args) {
  CLI::App* record = app.add_subcommand(
      "record",
      "Convert SOURCE into an OpenNI2 recording OUT.oni (+ OUT.gt.json) or a ROS 1 bag OUT.bag");
  record
      ->add_option("SOURCE", args.source,
                   "Dataset folder, .oni recording or synthetic scene (.yaml) to convert, or a "
                   "live device (openni2://[URI]) to record through OpenNI2's Recorder until "
                   "--max-frames or Ctrl-C")
      ->required();
  record
      ->add_option("OUT", args.output,
                   "The .oni file to write, or a ROS 1 bag (.bag): depth, colour and their "
                   "camera_info on the --topics set's names (default openni), ground truth on /tf")
      ->required();
  addCodecOptions(record, args);
  record
      ->add_option("--depth-encoding", args.depth_encoding,
                   ".bag: depth as 16UC1 millimetres or 32FC1 metres")
      ->check(CLI::IsMember({"16UC1", "32FC1"}))
      ->capture_default_str();
  record
      ->add_option("--colour-encoding", args.colour_encoding,
                   ".bag: colour as rgb8, bgr8, bayer_rggb8, bayer_bggr8, bayer_gbrg8, "
                   "bayer_grbg8, yuv422 (UYVY) or yuv422_yuy2")
      ->check(CLI::IsMember({"rgb8", "bgr8", "bayer_rggb8", "bayer_bggr8", "bayer_gbrg8",
                             "bayer_grbg8", "yuv422", "yuv422_yuy2"}))
      ->capture_default_str();
  record->add_flag("--lz4", args.bag_lz4, ".bag: compress the bag's chunks with LZ4");
  record
      ->add_option("--compressed", args.bag_compressed,
                   ".bag: write image_transport's compressed topics instead of raw images, as "
                   "robots record them: depth on DEPTH/compressedDepth (16-bit PNG, lossless), "
                   "colour on COLOUR/compressed as png (lossless) or jpeg (quality 95)")
      ->check(CLI::IsMember({"png", "jpeg"}));
  addSourceOptions(*record, args.source_args);
  return record;
}

int recordCommand(const RecordArguments& args) {
  try {
    if (drivers::openni2::parseOpenNi2Uri(args.source)) {
      if (isBagOutput(args)) {
        throw core::ConfigError(fmt::format(
            "{}: a live OpenNI2 device records through OpenNI2's Recorder, to .oni only",
            args.output));
      }
      return recordLive(args);
    }
    auto source = openSource(args.source, args.source_args);
    if (source->isLive()) {
      throw core::ConfigError(fmt::format(
          "{}: only OpenNI2 devices (openni2://) can be recorded, through OpenNI2's Recorder; "
          "open a Kinect v1 through OpenNI2 to record it",
          args.source));
    }
    if (isBagOutput(args)) return recordBag(*source, args);
    return recordFrames(*source, args, nlohmann::json::object());
  } catch (const core::Error& e) {
    spdlog::error("{}", e.what());
    return 1;
  }
}

CLI::App* addSynthCommand(CLI::App& app, RecordArguments& args) {
  CLI::App* synth = app.add_subcommand(
      "synth", "Render a synthetic scene (YAML) into an OpenNI2 recording with exact ground truth");
  synth->add_option("SCENE", args.source, "Scene file, e.g. config/scenes/office.yaml")
      ->required()
      ->check(CLI::ExistingFile);
  synth->add_option("OUT", args.output, "The .oni file to write (ground truth: OUT.gt.json)")
      ->required();
  addCodecOptions(synth, args);
  synth->add_option(
      "--sensor", args.sensor,
      "Sensor profile instead of the scene's: " + drivers::synthetic::SensorProfile::knownNames());
  synth
      ->add_option("--max-frames", args.source_args.max_frames,
                   "Render only this many frames (0: all)")
      ->capture_default_str();
  return synth;
}

int synthCommand(const RecordArguments& args) {
  try {
    drivers::synthetic::SyntheticSource source(args.source);
    if (!args.sensor.empty()) {
      try {
        source.useSensor(drivers::synthetic::SensorProfile::named(args.sensor));
      } catch (const core::ConfigError& e) {
        throw core::Error(fmt::format("--sensor: {}", e.what()));
      }
    }
    return recordFrames(source, args, drivers::synthetic::sceneGroundTruth(source.scene()));
  } catch (const core::Error& e) {
    spdlog::error("{}", e.what());
    return 1;
  }
}

}  // namespace tessera::cli
