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

}  // namespace tessera::core
