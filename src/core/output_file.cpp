#include "tessera/core/output_file.h"

#include <fmt/format.h>

#include "tessera/core/error.h"

namespace tessera::core {

std::ofstream createOutputFile(const std::filesystem::path& path) {
  std::ofstream out(path);
  if (!out) throw Error(fmt::format("{}: cannot be created", path.string()));
  return out;
}

void finishOutputFile(std::ofstream& out, const std::filesystem::path& path) {
  out.close();
  if (!out) throw Error(fmt::format("{}: could not be written (disk full?)", path.string()));
}

void linkOrCopy(const std::filesystem::path& from, const std::filesystem::path& to) {
  std::error_code ec;
  std::filesystem::remove(to, ec);
  std::filesystem::create_hard_link(from, to, ec);
  if (ec) std::filesystem::copy_file(from, to);
}

}  // namespace tessera::core
