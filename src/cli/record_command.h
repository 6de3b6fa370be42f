#pragma once
// `tessera record SOURCE OUT.oni`: converts any source into an OpenNI2 recording plus its
// ground-truth sidecar OUT.gt.json, or into a ROS 1 bag (OUT.bag).
#include <string>

#include <CLI/CLI.hpp>

#include "source_factory.h"

namespace tessera::cli {

struct RecordArguments {
  std::string source;
  std::string output;
  std::string depth_codec = "16zT";
  std::string colour_codec = "jpeg";
  int jpeg_quality = 90;
  std::string depth_encoding = "16UC1";  // .bag output
  std::string colour_encoding = "rgb8";  // .bag output
  bool bag_lz4 = false;                  // .bag output: LZ4 chunks
  std::string bag_compressed;            // .bag output: "" raw, or png / jpeg transports
  std::string sensor;  // synth: a named sensor profile instead of the scene's
  SourceArguments source_args;
};

CLI::App* addRecordCommand(CLI::App& app, RecordArguments& args);

// Returns the process exit code. Errors are logged, never thrown.
int recordCommand(const RecordArguments& args);

// `tessera synth SCENE.yaml OUT.oni`: renders a synthetic scene into a recording whose
// sidecar also holds the scene's planes, textures and sensor.
CLI::App* addSynthCommand(CLI::App& app, RecordArguments& args);
int synthCommand(const RecordArguments& args);

}  // namespace tessera::cli
