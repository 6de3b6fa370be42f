#include "source_factory.h"

#include <cstdlib>
#include <vector>

#include <fmt/format.h>

#include "tessera/core/error.h"

namespace tessera::cli {

namespace fs = std::filesystem;

namespace {
constexpr const char* kDefaultRecording = "tum_fr1_rpy_20";
}

std::unique_ptr<core::FrameSource> openSource(const std::string& spec,
                                              const drivers::DatasetOptions& options) {
  std::error_code ec;
  if (fs::is_directory(spec, ec)) return std::make_unique<drivers::DatasetSource>(spec, options);
  if (fs::exists(spec, ec)) {
    throw core::SourceError(fmt::format(
        "{}: not a source tessera can read yet; SOURCE must be a recorded dataset folder "
        "(TUM RGB-D, 7-Scenes, Redwood or slambook layout)",
        spec));
  }
  throw core::SourceError(fmt::format("{}: no such file or folder", spec));
}

fs::path defaultRecording() {
  std::vector<fs::path> candidates;
  if (const char* env = std::getenv("TESSERA_RECORDINGS")) candidates.emplace_back(env);
  candidates.emplace_back("recordings");
  candidates.emplace_back(fs::path(TESSERA_SOURCE_DIR) / "recordings");
  for (const fs::path& dir : candidates) {
    std::error_code ec;
    if (fs::is_directory(dir / kDefaultRecording, ec)) return dir / kDefaultRecording;
  }
  throw core::SourceError(fmt::format(
      "no SOURCE given and the default recording '{}' was not found in $TESSERA_RECORDINGS, "
      "./recordings or {}/recordings",
      kDefaultRecording, TESSERA_SOURCE_DIR));
}

}  // namespace tessera::cli
