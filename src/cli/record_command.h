#pragma once
// `tessera record SOURCE OUT.oni`: converts any source into an OpenNI2 recording plus its
// ground-truth sidecar OUT.gt.json.
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
