#include "tessera/planes/patch_export.h"

#include <fstream>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "tessera/core/error.h"

namespace tessera::planes {

namespace {

void checkWritten(std::ofstream& out, const std::filesystem::path& path) {
  out.close();
  if (!out) throw core::Error(fmt::format("{}: could not be written (disk full?)", path.string()));
}

std::ofstream openForWriting(const std::filesystem::path& path) {
  std::ofstream out(path);
  if (!out) throw core::Error(fmt::format("{}: cannot be created", path.string()));
  return out;
}

Eigen::Vector3d toWorld(const Patch::Frame& frame, double u, double v) {
  return frame.origin + u * frame.u_axis + v * frame.v_axis;
}

nlohmann::json polygonJson(const Polygon2& polygon) {
  nlohmann::json points = nlohmann::json::array();
  for (const Eigen::Vector2d& p : polygon) points.push_back({p.x(), p.y()});
  return points;
}

nlohmann::json vectorJson(const Eigen::Vector3d& v) { return {v.x(), v.y(), v.z()}; }

}  // namespace

void writePatchesObj(const PatchMap& map, const std::filesystem::path& path) {
  std::ofstream out = openForWriting(path);
  out << "# tessera finalized planar patches (untextured)\n";
  const double cell = map.config().cell_m;
  std::size_t vertices = 0;
  for (const Patch& patch : map.patches()) {
    if (!patch.finalized) continue;
    const Outline outline = map.outlineOf(patch);
    const Patch::Frame frame = patch.planeFrame();
    out << fmt::format("o patch_{}_v{}\n", patch.id, patch.version);
    auto vertex = [&](double u, double v) {
      const Eigen::Vector3d X = toWorld(frame, u, v);
      out << fmt::format("v {:.4f} {:.4f} {:.4f}\n", X.x(), X.y(), X.z());
      return ++vertices;
    };
    for (int r = 0; r < outline.grid.rows; ++r) {
      const auto* row = outline.grid.ptr<std::uint8_t>(r);
      for (int c = 0; c < outline.grid.cols;) {
        if (row[c] == 0) {
          ++c;
          continue;
        }
        const int start = c;
        while (c < outline.grid.cols && row[c] != 0) ++c;
        const double u0 = (outline.first_cell.first + start) * cell;
        const double u1 = (outline.first_cell.first + c) * cell;
        const double v0 = (outline.first_cell.second + r) * cell;
        const double v1 = v0 + cell;
        const std::size_t a = vertex(u0, v0), b = vertex(u1, v0), d = vertex(u1, v1),
                          e = vertex(u0, v1);
        out << fmt::format("f {} {} {} {}\n", a, b, d, e);
      }
    }
    auto polyline = [&](const Polygon2& polygon) {
      const std::size_t first = vertices + 1;
      for (const Eigen::Vector2d& p : polygon) vertex(p.x(), p.y());
      out << 'l';
      for (std::size_t i = 0; i < polygon.size(); ++i) out << ' ' << first + i;
      out << ' ' << first << '\n';
    };
    for (const OutlinePart& part : outline.parts) {
      polyline(part.outer);
      for (const Polygon2& hole : part.holes) polyline(hole);
    }
  }
  checkWritten(out, path);
}

void writePatchesJson(const PatchMap& map, const std::filesystem::path& path) {
  nlohmann::json patches = nlohmann::json::array();
  for (const Patch& patch : map.patches()) {
    if (!patch.finalized) continue;
    const Outline outline = map.outlineOf(patch);
    const Patch::Frame frame = patch.planeFrame();
    nlohmann::json parts = nlohmann::json::array();
    for (const OutlinePart& part : outline.parts) {
      nlohmann::json holes = nlohmann::json::array();
      for (const Polygon2& hole : part.holes) holes.push_back(polygonJson(hole));
      parts.push_back({{"outer", polygonJson(part.outer)}, {"holes", holes}});
    }
    patches.push_back({{"id", patch.id},
                       {"version", patch.version},
                       {"normal", vectorJson(patch.normal)},
                       {"offset_m", patch.offset},
                       {"origin", vectorJson(frame.origin)},
                       {"u_axis", vectorJson(frame.u_axis)},
                       {"v_axis", vectorJson(frame.v_axis)},
                       {"area_m2", outline.area_m2},
                       {"colour_samples", patch.samples.size()},
                       {"outline", parts}});
  }
  std::ofstream out = openForWriting(path);
  out << nlohmann::json{{"format", "tessera patches 1"},
                        {"cell_m", map.config().cell_m},
                        {"patches", patches}}
             .dump(1)
      << '\n';
  checkWritten(out, path);
}

}  // namespace tessera::planes
