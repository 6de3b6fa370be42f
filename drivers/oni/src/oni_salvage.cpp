#include "internal/oni_salvage.h"

#include <cstring>
#include <fstream>

#include <fmt/format.h>

#include "internal/oni_format.h"
#include "tessera/core/error.h"

namespace tessera::drivers::oni::internal {

namespace {

using namespace format;  // NOLINT: the record names read best unqualified here

template <typename T>
T readLe(const unsigned char* p) {
  T value{};
  std::memcpy(&value, p, sizeof(T));  // the format and x86 are both little-endian
  return value;
}

}  // namespace

OniDiagnosis diagnoseOni(const std::filesystem::path& path) {
  OniDiagnosis result;
  std::ifstream in(path, std::ios::binary);
  const auto size = std::filesystem::file_size(path);
  unsigned char header[kFileHeaderBytes];
  if (!in.read(reinterpret_cast<char*>(header), kFileHeaderBytes) ||
      std::memcmp(header, "NI10", 4) != 0) {
    result.problem = "not an ONI recording (no NI10 header)";
    return result;
  }
  const unsigned major = header[4], minor = header[5];
  const auto maintenance = readLe<std::uint16_t>(header + 6);
  if (major != 1 || minor != 0 || maintenance > 1) {
    result.problem =
        fmt::format("ONI version {}.{}.{} is not one OpenNI2 plays", major, minor, maintenance);
    return result;
  }
  result.header_ok = true;
  std::uint64_t offset = kFileHeaderBytes;
  std::uint32_t depth_node = 0;
  std::vector<unsigned char> fields;
  while (offset < size) {
    unsigned char record[28];
    in.seekg(static_cast<std::streamoff>(offset));
    if (offset + 28 > size || !in.read(reinterpret_cast<char*>(record), 28)) break;
    const auto magic = readLe<std::uint32_t>(record);
    const auto type = readLe<std::uint32_t>(record + 4);
    const auto node = readLe<std::uint32_t>(record + 8);
    const auto fields_size = readLe<std::uint32_t>(record + 12);
    const auto payload_size = readLe<std::uint32_t>(record + 16);
    if (magic != kRecordMagic || fields_size < 28) {
      result.problem = fmt::format("corrupt record at byte {}", offset);
      result.good_bytes = offset;
      return result;
    }
    const std::uint64_t next = offset + fields_size + payload_size;
    if (next > size) break;  // cut inside this record
    if (type == kNodeAdded) {
      fields.resize(fields_size);
      in.seekg(static_cast<std::streamoff>(offset));
      in.read(reinterpret_cast<char*>(fields.data()), fields_size);
      const auto name_length = readLe<std::uint32_t>(fields.data() + 28);
      if (32 + name_length + 4 <= fields_size &&
          readLe<std::uint32_t>(fields.data() + 32 + name_length) == kDepthNode &&
          depth_node == 0) {
        depth_node = node;
      }
      result.stream_header_offsets.push_back(offset);
    } else if (type == kNewData && node == depth_node) {
      ++result.depth_frames;
    } else if (type == kEnd) {
      result.complete = true;
      result.good_bytes = next;
      return result;
    }
    offset = next;
    result.good_bytes = offset;
  }
  result.problem =
      fmt::format("truncated at byte {} of {} (no end record)", result.good_bytes, size);
  return result;
}

void writePlayableCopy(const std::filesystem::path& path, const OniDiagnosis& diagnosis,
                       const std::filesystem::path& copy) {
  std::vector<char> bytes(diagnosis.good_bytes);
  std::ifstream in(path, std::ios::binary);
  in.read(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  for (const std::uint64_t offset : diagnosis.stream_header_offsets) {
    // Node-added fields after the name: type, codec, frames, min ts, max ts, seek-table offset.
    std::uint32_t name_length;
    std::memcpy(&name_length, bytes.data() + offset + 28, 4);
    char* tail = bytes.data() + offset + 32 + name_length + 8;
    const std::uint32_t unknown_frames = 0xFFFFFFFF;
    const std::uint64_t no_limit = ~std::uint64_t{0}, no_table = 0;
    std::memcpy(tail, &unknown_frames, 4);
    std::memcpy(tail + 12, &no_limit, 8);
    std::memcpy(tail + 20, &no_table, 8);
  }
  // End with an end record, as a complete file does. Without one, OpenNI2's player thread
  // runs off the end of the file and sometimes crashes while the device is being closed.
  unsigned char end[kRecordHeaderBytes] = {};
  const std::uint32_t end_fields[5] = {kRecordMagic, kEnd, 0,
                                       static_cast<std::uint32_t>(kRecordHeaderBytes), 0};
  std::memcpy(end, end_fields, sizeof(end_fields));  // then an undo offset of 0
  std::ofstream out(copy, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  out.write(reinterpret_cast<const char*>(end), sizeof(end));
  out.close();
  if (!in || !out) {
    throw core::Error(
        fmt::format("{}: cannot write a playable copy of {}", copy.string(), path.string()));
  }
}

}  // namespace tessera::drivers::oni::internal
