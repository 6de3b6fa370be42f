#pragma once
// A structural check of .oni files, used only when OpenNI2 refuses one: it tells what is wrong
// and, for a truncated file, makes a copy OpenNI2 can play up to the cut. Playback itself
// always goes through OpenNI2.
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

namespace tessera::drivers::oni::internal {

struct OniDiagnosis {
  bool header_ok = false;
  bool complete = false;         // reached the end record
  std::string problem;           // what is wrong, for messages ("" when nothing)
  std::uint64_t good_bytes = 0;  // bytes up to the end of the last whole record
  std::size_t depth_frames = 0;  // whole frame records of the first depth stream
  std::vector<std::uint64_t> stream_header_offsets;  // node-added records
};

OniDiagnosis diagnoseOni(const std::filesystem::path& path);

// Copies the whole records of a truncated file to `copy`, with the stream headers reset to
// "length unknown, no seek table" and an end record after the last whole record, so that
// OpenNI2 opens and plays it as it plays a complete file. Throws core::Error on I/O failure.
void writePlayableCopy(const std::filesystem::path& path, const OniDiagnosis& diagnosis,
                       const std::filesystem::path& copy);

}  // namespace tessera::drivers::oni::internal
