#pragma once
// Little binary files of plain values (a map's saved state): a magic tag and a format version
// up front, then values as they lie in memory (the machine that wrote them reads them). A file
// that is cut short or holds impossible sizes gives one core::Error naming it.
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>
#include <type_traits>
#include <vector>

#include <fmt/format.h>

#include "tessera/core/error.h"

namespace tessera::core {

class BinaryWriter {
 public:
  // Creates `path` and writes the tag and version; throws core::Error naming it on failure.
  BinaryWriter(std::filesystem::path path, const std::string& tag, std::uint32_t version)
      : path_(std::move(path)), out_(path_, std::ios::binary | std::ios::trunc) {
    if (!out_) throw Error(fmt::format("{}: cannot create the file", path_.string()));
    bytes(tag.data(), tag.size());
    value(version);
  }
  template <typename T>
  void value(const T& v) {
    static_assert(std::is_trivially_copyable_v<T>);
    bytes(&v, sizeof v);
  }
  template <typename T>
  void values(const std::vector<T>& v) {
    static_assert(std::is_trivially_copyable_v<T>);
    value(static_cast<std::uint64_t>(v.size()));
    bytes(v.data(), v.size() * sizeof(T));
  }
  void bytes(const void* data, std::size_t size) {
    out_.write(static_cast<const char*>(data), static_cast<std::streamsize>(size));
  }
  // Closes the file; throws core::Error naming it if anything was lost (a full disk).
  void finish() {
    out_.close();
    if (!out_) throw Error(fmt::format("{}: could not be written (disk full?)", path_.string()));
  }

 private:
  std::filesystem::path path_;
  std::ofstream out_;
};

class BinaryReader {
 public:
  // Opens `path` and checks its tag; the version read must be at most `newest` (a file from a
  // newer tessera is refused by name).
  BinaryReader(std::filesystem::path path, const std::string& tag, std::uint32_t newest)
      : path_(std::move(path)), in_(path_, std::ios::binary) {
    if (!in_) throw Error(fmt::format("{}: cannot be opened", path_.string()));
    std::error_code ec;
    size_ = std::filesystem::file_size(path_, ec);
    if (ec) throw Error(fmt::format("{}: cannot be read ({})", path_.string(), ec.message()));
    std::string found(tag.size(), '\0');
    bytes(found.data(), found.size());
    if (found != tag) throw Error(fmt::format("{}: not a {} file", path_.string(), tag));
    version_ = value<std::uint32_t>();
    if (version_ > newest) {
      throw Error(fmt::format("{}: written by a newer tessera (format {}, this one reads up to {})",
                              path_.string(), version_, newest));
    }
  }
  std::uint32_t version() const { return version_; }
  template <typename T>
  T value() {
    static_assert(std::is_trivially_copyable_v<T>);
    T v{};
    bytes(&v, sizeof v);
    return v;
  }
  // A count of at most `max` items of at least `item_bytes` each, that fit in what is left of
  // the file: a corrupt count does not make the reader allocate without bound.
  std::size_t count(std::size_t max, std::size_t item_bytes = 1) {
    const auto n = value<std::uint64_t>();
    if (n > max) corrupt(fmt::format("a count of {} (at most {} expected)", n, max));
    if (n * item_bytes > bytesLeft()) {
      corrupt(fmt::format("a count of {} items of {} bytes in the {} bytes left", n, item_bytes,
                          bytesLeft()));
    }
    return static_cast<std::size_t>(n);
  }
  template <typename T>
  std::vector<T> values(std::size_t max) {
    static_assert(std::is_trivially_copyable_v<T>);
    std::vector<T> v(count(max, sizeof(T)));
    bytes(v.data(), v.size() * sizeof(T));
    return v;
  }
  void bytes(void* data, std::size_t size) {
    in_.read(static_cast<char*>(data), static_cast<std::streamsize>(size));
    if (!in_) corrupt("cut short");
  }
  [[noreturn]] void corrupt(const std::string& what) const {
    throw Error(fmt::format("{}: corrupt ({})", path_.string(), what));
  }
  std::uint64_t bytesLeft() {
    const auto at = static_cast<std::uint64_t>(in_.tellg());
    return at < size_ ? size_ - at : 0;
  }
  // Throws unless the whole file was read.
  void expectEnd() {
    if (in_.peek() != std::char_traits<char>::eof()) corrupt("data after its end");
  }

 private:
  std::filesystem::path path_;
  std::ifstream in_;
  std::uint64_t size_ = 0;
  std::uint32_t version_ = 0;
};

}  // namespace tessera::core
