#pragma once
// A file's size for the stores' statistics: 0 when it is missing or cannot be read.
#include <cstddef>
#include <filesystem>
#include <system_error>

namespace tessera::db::internal {

inline std::size_t fileBytes(const std::filesystem::path& path) {
  std::error_code ec;
  const std::uintmax_t bytes = std::filesystem::file_size(path, ec);
  return ec ? 0 : static_cast<std::size_t>(bytes);
}

}  // namespace tessera::db::internal
