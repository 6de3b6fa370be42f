// Redwood / Open3D test data folders: color/ and depth/ (millimetres), an optional rgbd.match
// pairing them, a .log trajectory (per frame "id id n" then a 4x4 camera-to-world matrix) and
// an Open3D PinholeCameraIntrinsic JSON file.
#include <fstream>
#include <sstream>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "internal/layouts.h"
#include "tessera/core/error.h"

namespace tessera::drivers::internal {

namespace {

std::vector<core::Isometry> readLogTrajectory(const std::filesystem::path& path) {
  const std::vector<std::string> lines = readDataLines(path);
  if (lines.size() % 5 != 0) {
    throw core::SourceError(fmt::format("{}: a .log trajectory has 5 lines per frame, found {}",
                                        path.string(), lines.size()));
  }
  std::vector<core::Isometry> poses;
  for (std::size_t i = 0; i < lines.size(); i += 5) {
    Eigen::Matrix4d m;
    for (int r = 0; r < 4; ++r) {
      std::istringstream in(lines[i + 1 + static_cast<std::size_t>(r)]);
      for (int c = 0; c < 4; ++c) {
        if (!(in >> m(r, c))) {
          throw core::SourceError(
              fmt::format("{}: malformed matrix row near line {}", path.string(), i + 2));
        }
      }
    }
    poses.emplace_back(m);
  }
  return poses;
}

// The first JSON file in `dir` holding an Open3D "intrinsic_matrix" (column-major 3x3).
std::optional<core::Intrinsics> findIntrinsicJson(const std::filesystem::path& dir,
                                                  std::string& origin) {
  for (const auto& file : sortedFiles(dir)) {
    if (file.extension() != ".json") continue;
    std::ifstream in(file);
    const nlohmann::json json = nlohmann::json::parse(in, nullptr, /*allow_exceptions=*/false);
    if (json.is_discarded() || !json.contains("intrinsic_matrix")) continue;
    const auto& m = json["intrinsic_matrix"];
    if (!m.is_array() || m.size() != 9) {
      throw core::SourceError(
          fmt::format("{}: intrinsic_matrix must have 9 numbers", file.string()));
    }
    core::Intrinsics k;
    k.width = json.value("width", 0);
    k.height = json.value("height", 0);
    k.fx = m[0].get<double>(), k.fy = m[4].get<double>();
    k.cx = m[6].get<double>(), k.cy = m[7].get<double>();
    origin = file.string();
    return k;
  }
  return std::nullopt;
}

}  // namespace

DatasetListing listRedwood(const std::filesystem::path& dir) {
  DatasetListing listing;
  listing.depth_units_per_m = 1000.0;

  std::vector<std::pair<std::filesystem::path, std::filesystem::path>> pairs;  // rgb, depth
  if (std::filesystem::exists(dir / "rgbd.match")) {
    for (const std::string& line : readDataLines(dir / "rgbd.match")) {
      std::istringstream in(line);
      std::string depth, color;
      if (!(in >> depth >> color)) {
        throw core::SourceError(
            fmt::format("{}: malformed line '{}'", (dir / "rgbd.match").string(), line));
      }
      pairs.emplace_back(dir / color, dir / depth);
    }
  } else {
    const auto colors = sortedFiles(dir / "color");
    const auto depths = sortedFiles(dir / "depth");
    if (colors.size() != depths.size()) {
      throw core::SourceError(fmt::format("{}: color/ has {} images but depth/ has {}",
                                          dir.string(), colors.size(), depths.size()));
    }
    for (std::size_t i = 0; i < colors.size(); ++i) pairs.emplace_back(colors[i], depths[i]);
  }

  std::vector<core::Isometry> poses;
  if (std::filesystem::exists(dir / "trajectory.log")) {
    poses = readLogTrajectory(dir / "trajectory.log");
  }
  for (std::size_t i = 0; i < pairs.size(); ++i) {
    DatasetEntry entry;
    entry.rgb = pairs[i].first;
    entry.depth = pairs[i].second;
    entry.timestamp_ns = nominalTimestampNs(i);
    if (i < poses.size()) entry.T_W_C = poses[i];
    listing.entries.push_back(std::move(entry));
  }
  listing.intrinsics = findIntrinsicJson(dir, listing.intrinsics_origin);
  return listing;
}

}  // namespace tessera::drivers::internal
