#pragma once
// Turns a SOURCE argument into a FrameSource: the one place that knows every driver.
#include <filesystem>
#include <memory>
#include <optional>
#include <string>

#include "tessera/core/frame_source.h"
#include "tessera/drivers/dataset_source.h"

namespace tessera::cli {

// Opens a dataset folder. Throws core::SourceError naming SOURCE and what tessera can read.
std::unique_ptr<core::FrameSource> openSource(const std::string& spec,
                                              const drivers::DatasetOptions& options);

// The recording `tessera run` replays when no SOURCE is given: $TESSERA_RECORDINGS, then
// ./recordings, then the source tree's recordings/. Throws core::SourceError when none exists.
std::filesystem::path defaultRecording();

}  // namespace tessera::cli
