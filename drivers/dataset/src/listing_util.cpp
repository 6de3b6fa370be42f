#include <algorithm>
#include <cctype>
#include <fstream>

#include <fmt/format.h>

#include "internal/layouts.h"
#include "tessera/core/error.h"

namespace tessera::drivers::internal {

std::int64_t parseSecondsToNs(const std::string& text, const std::string& where) {
  const std::size_t dot = text.find('.');
  const std::string whole = text.substr(0, dot);
  std::string fraction = dot == std::string::npos ? "" : text.substr(dot + 1);
  const auto all_digits = [](const std::string& s) {
    return std::all_of(s.begin(), s.end(), [](unsigned char c) { return std::isdigit(c); });
  };
  if (whole.empty() || whole.size() > 11 || !all_digits(whole) || !all_digits(fraction)) {
    throw core::SourceError(fmt::format("{}: '{}' is not a timestamp in seconds", where, text));
  }
  fraction.resize(9, '0');  // pad or cut to nanoseconds
  return std::stoll(whole) * 1'000'000'000LL + std::stoll(fraction);
}

std::vector<std::string> readDataLines(const std::filesystem::path& path) {
  std::ifstream file(path);
  if (!file) throw core::SourceError(fmt::format("{}: cannot open", path.string()));
  std::vector<std::string> lines;
  std::string line;
  while (std::getline(file, line)) {
    if (!line.empty() && line.back() == '\r') line.pop_back();
    const std::size_t first = line.find_first_not_of(" \t");
    if (first == std::string::npos || line[first] == '#') continue;
    lines.push_back(line.substr(first));
  }
  return lines;
}

std::vector<std::filesystem::path> sortedFiles(const std::filesystem::path& dir) {
  std::vector<std::filesystem::path> files;
  std::error_code ec;
  for (const auto& entry : std::filesystem::directory_iterator(dir, ec)) {
    if (entry.is_regular_file()) files.push_back(entry.path());
  }
  if (ec) throw core::SourceError(fmt::format("{}: cannot list: {}", dir.string(), ec.message()));
  const auto numeric = [](const std::filesystem::path& p) {
    const std::string stem = p.stem().string();
    return !stem.empty() &&
           std::all_of(stem.begin(), stem.end(), [](unsigned char c) { return std::isdigit(c); });
  };
  std::sort(files.begin(), files.end(), [&](const auto& a, const auto& b) {
    if (numeric(a) && numeric(b) && a.stem().string().size() < 19 &&
        b.stem().string().size() < 19) {
      return std::stoll(a.stem().string()) < std::stoll(b.stem().string());
    }
    return a.filename() < b.filename();
  });
  return files;
}

std::int64_t nominalTimestampNs(std::size_t index) {
  return static_cast<std::int64_t>(index) * 1'000'000'000LL / 30;
}

}  // namespace tessera::drivers::internal
