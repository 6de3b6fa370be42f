#include "internal/fakenect_dump.h"

#include <link.h>

#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <string_view>
#include <vector>

#include <fmt/format.h>

#include "tessera/core/error.h"

namespace tessera::drivers::freenect {

namespace {

constexpr std::size_t kDepthBytes = 640 * 480 * 2;   // FREENECT_DEPTH_11BIT
constexpr std::size_t kColourBytes = 640 * 480 * 3;  // FREENECT_VIDEO_RGB
constexpr std::size_t kLongestHeader = 64;

int findFakenect(dl_phdr_info* info, std::size_t /*size*/, void* found) {
  const std::string_view name = info->dlpi_name == nullptr ? "" : info->dlpi_name;
  if (name.find("fakenect/libfreenect") != std::string_view::npos) {
    *static_cast<bool*>(found) = true;
    return 1;
  }
  return 0;
}

// Throws unless `path` holds a one-line header followed by at least `frame_bytes` bytes.
void checkFrameFile(const std::filesystem::path& path, std::size_t frame_bytes, const char* what) {
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    throw core::SourceError(
        fmt::format("fakenect dump: {} is listed in INDEX.txt but cannot be "
                    "read",
                    path.string()));
  }
  std::vector<char> head(kLongestHeader);
  in.read(head.data(), static_cast<std::streamsize>(head.size()));
  const auto read = static_cast<std::size_t>(in.gcount());
  std::size_t header = 0;
  while (header < read && head[header] != '\n') ++header;
  if (header == read) {
    throw core::SourceError(fmt::format(
        "fakenect dump: {} has no header line (a P5/P6 line ending in a newline)", path.string()));
  }
  const std::uintmax_t size = std::filesystem::file_size(path);
  const std::uintmax_t payload = size - (header + 1);
  if (payload < frame_bytes) {
    throw core::SourceError(fmt::format(
        "fakenect dump: {} is truncated: {} bytes of {} after its header, a 640x480 frame needs {}",
        path.string(), payload, what, frame_bytes));
  }
}

}  // namespace

bool fakenectLoaded() {
  bool found = false;
  dl_iterate_phdr(findFakenect, &found);
  return found;
}

std::optional<std::filesystem::path> fakenectDump(const std::string& label) {
  if (!fakenectLoaded()) return std::nullopt;
  const char* path = std::getenv("FAKENECT_PATH");
  if (path == nullptr || *path == '\0') {
    throw core::SourceError(fmt::format(
        "{}: the libfreenect loaded is Debian's fakenect replay library (LD_LIBRARY_PATH), but "
        "FAKENECT_PATH names no dump folder to replay",
        label));
  }
  return std::filesystem::path(path);
}

std::size_t checkFakenectDump(const std::filesystem::path& folder) {
  const std::filesystem::path index = folder / "INDEX.txt";
  std::ifstream in(index);
  if (!in) {
    throw core::SourceError(
        fmt::format("fakenect dump: cannot read {} (is FAKENECT_PATH a dump folder recorded by "
                    "libfreenect's `record`?)",
                    index.string()));
  }
  std::size_t depth_frames = 0;
  double last_time = 0.0;
  std::string line;
  for (int number = 1; std::getline(in, line) && !line.empty(); ++number) {
    char type = 0;
    double host_time = 0.0;
    unsigned int stamp = 0;
    if (std::sscanf(line.c_str(), "%c-%lf-%u", &type, &host_time, &stamp) != 3) {
      throw core::SourceError(fmt::format(
          "fakenect dump: {} line {}: '{}' is not a TYPE-HOSTTIME-TIMESTAMP-... file name",
          index.string(), number, line));
    }
    if (host_time < last_time) {
      throw core::SourceError(
          fmt::format("fakenect dump: {} line {}: '{}' goes back in time ({} s after {} s)",
                      index.string(), number, line, host_time, last_time));
    }
    last_time = host_time;
    const std::filesystem::path file = folder / line;
    if (type == 'd') {
      checkFrameFile(file, kDepthBytes, "depth");
      ++depth_frames;
    } else if (type == 'r') {
      checkFrameFile(file, kColourBytes, "RGB");
    } else if (!std::filesystem::is_regular_file(file)) {
      throw core::SourceError(
          fmt::format("fakenect dump: {} is listed in INDEX.txt but missing", file.string()));
    }
  }
  return depth_frames;
}

}  // namespace tessera::drivers::freenect
