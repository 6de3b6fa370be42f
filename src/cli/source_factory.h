#pragma once
// Turns a SOURCE argument into a FrameSource: the one place that knows every driver.
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "tessera/core/frame_source.h"

namespace tessera::cli {

// The source options every subcommand that reads frames shares.
struct SourceArguments {
  std::string intrinsics;          // --intrinsics
  double depth_units_per_m = 0.0;  // --depth-scale, 0: the source's own
  std::size_t max_frames = 0;      // --max-frames, 0: all
  int bounce = 1;                  // --bounce: passes back and forth over a recording
  // Live devices (openni2://).
  std::string depth_mode = "640x480@30";   // --depth-mode
  std::string colour_mode = "640x480@30";  // --colour-mode
  double reconnect_timeout_s = 10.0;       // --reconnect-timeout
  int frame_timeout_ms = 2000;             // --frame-timeout
  std::string calibration;                 // --calibration: host-side colour registration
  std::string record_path;  // set by `run --record` and `record`: the device records itself
  // ROS 1 bags (.bag) and the ROS graph (ros://).
  std::string topic_set;                  // --topics: openni or tum; default: what the bag has
  std::vector<std::string> topic_remaps;  // --topic ROLE:=TOPIC
  std::string world_frame = "world";      // --world-frame
  std::string camera_frame;               // --camera-frame
  double pair_tolerance_ms = 20.0;        // --pair-tolerance
};

void addSourceOptions(CLI::App& command, SourceArguments& args);

// Opens a dataset folder, an .oni recording, a synthetic scene or a live device (openni2://).
// Throws core::SourceError naming SOURCE and listing what tessera can read, or core::ConfigError
// for bad --intrinsics.
std::unique_ptr<core::FrameSource> openSource(const std::string& spec, const SourceArguments& args);

// The recording `tessera run` replays when no SOURCE is given: $TESSERA_RECORDINGS, then
// ./recordings, then the source tree's recordings/. Throws core::SourceError when none exists.
std::filesystem::path defaultRecording();

}  // namespace tessera::cli
