// 7-Scenes sequence folders: frame-NNNNNN.color.png, frame-NNNNNN.depth.png (millimetres,
// 65535 = invalid) and frame-NNNNNN.pose.txt (4x4 camera-to-world). Several public copies
// ship the colour as frame-NNNNNN.color.jpg (or .jpeg) instead.
#include <algorithm>
#include <array>
#include <fstream>
#include <string_view>

#include <fmt/format.h>

#include "internal/layouts.h"
#include "tessera/core/error.h"

namespace tessera::drivers::internal {

namespace {

constexpr const char* kPrefix = "frame-";
// In order of preference: a frame with several colour files is listed once, from the first.
constexpr std::array<std::string_view, 3> kColourSuffixes = {".color.png", ".color.jpg",
                                                             ".color.jpeg"};

Eigen::Matrix4d readMatrix4(const std::filesystem::path& path) {
  std::ifstream in(path);
  Eigen::Matrix4d m;
  for (int r = 0; r < 4; ++r) {
    for (int c = 0; c < 4; ++c) {
      if (!(in >> m(r, c))) {
        throw core::SourceError(fmt::format("{}: expected a 4x4 matrix", path.string()));
      }
    }
  }
  return m;
}

// camera-intrinsics.txt: a 3x3 camera matrix (fx 0 cx / 0 fy cy / 0 0 1).
core::Intrinsics readCameraMatrix(const std::filesystem::path& path) {
  std::ifstream in(path);
  double m[9];
  for (double& value : m) {
    if (!(in >> value)) {
      throw core::SourceError(fmt::format("{}: expected a 3x3 camera matrix", path.string()));
    }
  }
  core::Intrinsics k;
  k.fx = m[0], k.cx = m[2], k.fy = m[4], k.cy = m[5];
  return k;
}

}  // namespace

DatasetListing listSevenScenes(const std::filesystem::path& dir) {
  DatasetListing listing;
  listing.depth_units_per_m = 1000.0;
  listing.max_depth_is_invalid = true;
  for (const auto& file : sortedFiles(dir)) {
    const std::string name = file.filename().string();
    if (name.rfind(kPrefix, 0) != 0) continue;
    const auto suffix = std::find_if(kColourSuffixes.begin(), kColourSuffixes.end(),
                                     [&](std::string_view s) { return name.ends_with(s); });
    if (suffix == kColourSuffixes.end()) continue;
    const std::string stem = name.substr(0, name.size() - suffix->size());
    const bool preferred_exists = std::any_of(
        kColourSuffixes.begin(), suffix,
        [&](std::string_view s) { return std::filesystem::exists(dir / (stem + std::string(s))); });
    if (preferred_exists) continue;  // that file lists this frame
    DatasetEntry entry;
    entry.rgb = file;
    entry.depth = dir / (stem + ".depth.png");
    entry.timestamp_ns = nominalTimestampNs(listing.entries.size());
    const auto pose_file = dir / (stem + ".pose.txt");
    if (std::filesystem::exists(pose_file)) {
      const Eigen::Matrix4d m = readMatrix4(pose_file);
      if (m.allFinite()) entry.T_W_C = core::Isometry(m);  // invalid poses are stored as inf
    }
    listing.entries.push_back(std::move(entry));
  }
  const auto intrinsics_file = dir / "camera-intrinsics.txt";
  if (std::filesystem::exists(intrinsics_file)) {
    listing.intrinsics = readCameraMatrix(intrinsics_file);
    listing.intrinsics_origin = intrinsics_file.string();
  } else {
    // The dataset's published Kinect calibration (principal point 320,240; focal 585).
    core::Intrinsics k;
    k.width = 640, k.height = 480, k.fx = 585.0, k.fy = 585.0, k.cx = 320.0, k.cy = 240.0;
    listing.intrinsics = k;
    listing.intrinsics_origin = "7-Scenes published calibration";
  }
  return listing;
}

}  // namespace tessera::drivers::internal
