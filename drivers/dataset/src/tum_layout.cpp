// TUM RGB-D benchmark folders: rgb.txt, depth.txt, optional associations.txt and
// groundtruth.txt ("timestamp tx ty tz qx qy qz qw", camera pose in the world).
#include <algorithm>
#include <cctype>
#include <cmath>
#include <map>
#include <sstream>

#include <fmt/format.h>

#include "internal/layouts.h"
#include "tessera/core/error.h"
#include "tessera/core/trajectory.h"

namespace tessera::drivers::internal {

namespace {

struct Stamped {
  std::int64_t t_ns;
  std::string file;
};

std::vector<Stamped> readStampedList(const std::filesystem::path& path) {
  std::vector<Stamped> list;
  for (const std::string& line : readDataLines(path)) {
    std::istringstream in(line);
    std::string stamp, file;
    if (!(in >> stamp >> file)) {
      throw core::SourceError(fmt::format("{}: malformed line '{}'", path.string(), line));
    }
    list.push_back({parseSecondsToNs(stamp, path.string()), file});
  }
  return list;
}

// Greedy one-to-one association by nearest timestamp, as TUM's associate.py does
// (default maximum difference 0.02 s).
std::vector<std::pair<Stamped, Stamped>> associate(const std::vector<Stamped>& rgb,
                                                   const std::vector<Stamped>& depth) {
  constexpr std::int64_t kMaxDifferenceNs = 20'000'000;
  struct Candidate {
    std::int64_t diff;
    std::size_t r, d;
  };
  std::vector<Candidate> candidates;
  for (std::size_t r = 0; r < rgb.size(); ++r) {
    for (std::size_t d = 0; d < depth.size(); ++d) {
      const std::int64_t diff = std::llabs(rgb[r].t_ns - depth[d].t_ns);
      if (diff < kMaxDifferenceNs) candidates.push_back({diff, r, d});
    }
  }
  std::sort(candidates.begin(), candidates.end(),
            [](const Candidate& a, const Candidate& b) { return a.diff < b.diff; });
  std::vector<bool> rgb_used(rgb.size()), depth_used(depth.size());
  std::vector<std::pair<Stamped, Stamped>> pairs;
  for (const Candidate& c : candidates) {
    if (rgb_used[c.r] || depth_used[c.d]) continue;
    rgb_used[c.r] = depth_used[c.d] = true;
    pairs.emplace_back(rgb[c.r], depth[c.d]);
  }
  std::sort(pairs.begin(), pairs.end(),
            [](const auto& a, const auto& b) { return a.second.t_ns < b.second.t_ns; });
  return pairs;
}

std::vector<std::pair<Stamped, Stamped>> readAssociations(const std::filesystem::path& path) {
  std::vector<std::pair<Stamped, Stamped>> pairs;
  for (const std::string& line : readDataLines(path)) {
    std::istringstream in(line);
    std::string t1, f1, t2, f2;
    if (!(in >> t1 >> f1 >> t2 >> f2)) {
      throw core::SourceError(fmt::format("{}: malformed line '{}'", path.string(), line));
    }
    Stamped a{parseSecondsToNs(t1, path.string()), f1};
    Stamped b{parseSecondsToNs(t2, path.string()), f2};
    // Both column orders exist in the wild; the depth file is the one under depth/.
    if (f1.find("depth") != std::string::npos) std::swap(a, b);
    pairs.emplace_back(a, b);
  }
  return pairs;
}

// Ground truth keyed by time; poses are interpolated to frame times.
class Trajectory {
 public:
  explicit Trajectory(const std::filesystem::path& path) {
    for (const std::string& line : readDataLines(path)) {
      std::istringstream in(line);
      std::string stamp;
      double tx, ty, tz, qx, qy, qz, qw;
      if (!(in >> stamp >> tx >> ty >> tz >> qx >> qy >> qz >> qw)) {
        throw core::SourceError(fmt::format("{}: malformed line '{}'", path.string(), line));
      }
      poses_[parseSecondsToNs(stamp, path.string())] =
          core::isometryFromTranslationQuaternion({tx, ty, tz}, qx, qy, qz, qw);
    }
  }

  // Interpolated pose at t, or nothing when t is outside the trajectory or falls in a gap
  // longer than 0.1 s (the mocap lost the camera there).
  std::optional<core::Isometry> at(std::int64_t t_ns) const {
    return core::poseAt(poses_, t_ns, 100'000'000);
  }

 private:
  core::Trajectory poses_;
};

// Which TUM Kinect (1, 2 or 3) a folder name names: "freiburg1", "fr1", "fr_2", ... as a word
// of its own (preceded by a non-alphanumeric character or the start); 0 when none.
int tumCameraFromName(const std::string& folder_name) {
  std::string name = folder_name;
  for (char& c : name) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  for (const std::string prefix : {"freiburg", "fr"}) {
    for (std::size_t at = name.find(prefix); at != std::string::npos;
         at = name.find(prefix, at + 1)) {
      if (at > 0 && std::isalnum(static_cast<unsigned char>(name[at - 1]))) continue;
      std::size_t digit = at + prefix.size();
      if (digit < name.size() && name[digit] == '_') ++digit;
      if (digit >= name.size() || name[digit] < '1' || name[digit] > '3') continue;
      if (digit + 1 < name.size() && std::isdigit(static_cast<unsigned char>(name[digit + 1]))) {
        continue;
      }
      return name[digit] - '0';
    }
  }
  return 0;
}

// The published calibrations of the three TUM Kinects (vision.in.tum.de, "File Formats").
std::optional<core::Intrinsics> publishedTumIntrinsics(const std::string& folder_name,
                                                       std::string& origin) {
  const int camera = tumCameraFromName(folder_name);
  if (camera == 0) return std::nullopt;
  core::Intrinsics k;
  k.width = 640;
  k.height = 480;
  if (camera == 1) {
    k.fx = 517.3, k.fy = 516.5, k.cx = 318.6, k.cy = 255.3;
  } else if (camera == 2) {
    k.fx = 520.9, k.fy = 521.0, k.cx = 325.1, k.cy = 249.7;
  } else {
    k.fx = 535.4, k.fy = 539.2, k.cx = 320.1, k.cy = 247.6;
  }
  origin = fmt::format("TUM freiburg{} published calibration (from the folder name '{}')", camera,
                       folder_name);
  return k;
}

}  // namespace

DatasetListing listTum(const std::filesystem::path& dir) {
  DatasetListing listing;
  listing.depth_units_per_m = 5000.0;  // TUM: 16-bit PNG, metres = value / 5000

  const auto associations = dir / "associations.txt";
  const auto pairs =
      std::filesystem::exists(associations)
          ? readAssociations(associations)
          : associate(readStampedList(dir / "rgb.txt"), readStampedList(dir / "depth.txt"));
  std::optional<Trajectory> trajectory;
  if (std::filesystem::exists(dir / "groundtruth.txt")) trajectory.emplace(dir / "groundtruth.txt");

  for (const auto& [rgb, depth] : pairs) {
    DatasetEntry entry;
    entry.rgb = dir / rgb.file;
    entry.depth = dir / depth.file;
    entry.timestamp_ns = depth.t_ns;
    entry.colour_timestamp_ns = rgb.t_ns;
    if (trajectory) entry.T_W_C = trajectory->at(depth.t_ns);
    listing.entries.push_back(std::move(entry));
  }
  std::string folder = std::filesystem::absolute(dir).lexically_normal().filename().string();
  if (folder.empty()) folder = std::filesystem::absolute(dir).parent_path().filename().string();
  listing.intrinsics = publishedTumIntrinsics(folder, listing.intrinsics_origin);
  return listing;
}

}  // namespace tessera::drivers::internal
