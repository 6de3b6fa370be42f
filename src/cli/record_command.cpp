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
  ProgressLine progress;
  const auto start = std::chrono::steady_clock::now();
  std::size_t bad = 0;
  std::string end_problem;
  for (;;) {
    if (args.source_args.max_frames > 0 && writer &&
        writer->framesWritten() >= args.source_args.max_frames) {
      break;
    }
    core::ReadResult result = source.read();
    if (result.status == core::ReadStatus::kEndOfData) {
      end_problem = result.problem;
      break;
    }
    if (result.status == core::ReadStatus::kBadFrame) {
      ++bad;
      spdlog::warn("{}: skipped {}", source.name(), result.problem);
      continue;
    }
    const core::Frame& frame = result.frame;
    if (!writer) {
      options.with_colour = !frame.rgb.empty();
      writer = std::make_unique<drivers::oni::OniWriter>(args.output, frame.intrinsics,
                                                         frame.rgb.size(), options);
      ground_truth.setIntrinsics(frame.intrinsics);
      if (frame.colour_camera) ground_truth.setColourCamera(*frame.colour_camera);
    }
    writer->write(frame);
    ground_truth.addFrame(frame);
    const double elapsed =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    progress.update({writer->framesWritten(), source.frameCount(), elapsed, 0, std::nullopt});
  }
  progress.finish();
  if (!writer) throw core::SourceError(source.name() + ": no frame could be read");
  writer->close();
  for (const auto& [key, value] : extra.items()) ground_truth.extra()[key] = value;
  const auto sidecar = drivers::oni::groundTruthPath(args.output);
  ground_truth.write(sidecar);
  if (!end_problem.empty()) spdlog::error("{}", end_problem);
  spdlog::info(
      "wrote {} frames ({} bad skipped, {} with ground-truth pose) to {} ({:.1f} MB) and {}",
      writer->framesWritten(), bad, ground_truth.framesWithPose(), args.output,
      static_cast<double>(std::filesystem::file_size(args.output)) / 1e6, sidecar.string());
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  spdlog::info("{:.1f} s, {:.1f} frames/s", seconds,
               static_cast<double>(writer->framesWritten()) / seconds);
  return 0;
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
      "record", "Convert SOURCE into an OpenNI2 recording OUT.oni (+ OUT.gt.json)");
  record
      ->add_option("SOURCE", args.source,
                   "Dataset folder, .oni recording or synthetic scene (.yaml) to convert, or a "
                   "live device (openni2://[URI]) to record through OpenNI2's Recorder until "
                   "--max-frames or Ctrl-C")
      ->required();
  record->add_option("OUT", args.output, "The .oni file to write")->required();
  addCodecOptions(record, args);
  addSourceOptions(*record, args.source_args);
  return record;
}

int recordCommand(const RecordArguments& args) {
  try {
    if (drivers::openni2::parseOpenNi2Uri(args.source)) return recordLive(args);
    auto source = openSource(args.source, args.source_args);
    if (source->isLive()) {
      throw core::ConfigError(fmt::format(
          "{}: only OpenNI2 devices (openni2://) can be recorded, through OpenNI2's Recorder; "
          "open a Kinect v1 through OpenNI2 to record it",
          args.source));
    }
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
