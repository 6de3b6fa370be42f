#pragma once
// Per-layout folder readers. Each one lists the frames of a folder and says what the folder
// itself tells about intrinsics and depth units; DatasetSource does the reading.
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "tessera/core/intrinsics.h"
#include "tessera/drivers/dataset_source.h"

namespace tessera::drivers::internal {

struct DatasetListing {
  std::vector<DatasetEntry> entries;
  std::optional<core::Intrinsics> intrinsics;  // when the folder (or its name) implies them
  std::string intrinsics_origin;
  double depth_units_per_m = 1000.0;
  bool max_depth_is_invalid = false;
};

DatasetListing listTum(const std::filesystem::path& dir);
DatasetListing listSevenScenes(const std::filesystem::path& dir);
DatasetListing listRedwood(const std::filesystem::path& dir);
DatasetListing listSlambook(const std::filesystem::path& dir);

// "1305031234.893760" seconds -> nanoseconds, exactly (no double rounding).
// Throws core::SourceError naming `where` when malformed.
std::int64_t parseSecondsToNs(const std::string& text, const std::string& where);

// Non-empty lines of a text file that do not start with '#'. Throws core::SourceError.
std::vector<std::string> readDataLines(const std::filesystem::path& path);

// Regular files in `dir` sorted by name, with numeric stems sorted by value.
std::vector<std::filesystem::path> sortedFiles(const std::filesystem::path& dir);

// Nominal timestamps for layouts that have none: frame i at i / 30 s.
std::int64_t nominalTimestampNs(std::size_t index);

}  // namespace tessera::drivers::internal
