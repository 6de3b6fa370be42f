// The slambook layout: color/N.png, depth/N.pgm (16-bit big-endian millimetres) or
// depth/N.png (16-bit, 5000 units per metre as in its dense RGB-D chapter), and pose.txt with
// one "tx ty tz qx qy qz qw" camera-to-world pose per frame. It carries no intrinsics.
#include <sstream>

#include <fmt/format.h>

#include "internal/layouts.h"
#include "tessera/core/error.h"

namespace tessera::drivers::internal {

DatasetListing listSlambook(const std::filesystem::path& dir) {
  DatasetListing listing;
  const auto colors = sortedFiles(dir / "color");
  const auto depths = sortedFiles(dir / "depth");
  if (colors.size() != depths.size()) {
    throw core::SourceError(fmt::format("{}: color/ has {} images but depth/ has {}", dir.string(),
                                        colors.size(), depths.size()));
  }
  const bool png_depth = !depths.empty() && depths.front().extension() == ".png";
  listing.depth_units_per_m = png_depth ? 5000.0 : 1000.0;

  const std::vector<std::string> pose_lines = readDataLines(dir / "pose.txt");
  for (std::size_t i = 0; i < colors.size(); ++i) {
    DatasetEntry entry;
    entry.rgb = colors[i];
    entry.depth = depths[i];
    entry.timestamp_ns = nominalTimestampNs(i);
    if (i < pose_lines.size()) {
      std::istringstream in(pose_lines[i]);
      double tx, ty, tz, qx, qy, qz, qw;
      if (!(in >> tx >> ty >> tz >> qx >> qy >> qz >> qw)) {
        throw core::SourceError(
            fmt::format("{}: malformed pose on line {}", (dir / "pose.txt").string(), i + 1));
      }
      entry.T_W_C = core::isometryFromTranslationQuaternion({tx, ty, tz}, qx, qy, qz, qw);
    }
    listing.entries.push_back(std::move(entry));
  }
  return listing;
}

}  // namespace tessera::drivers::internal
