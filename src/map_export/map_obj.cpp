// map.obj and map.mtl (Wavefront).
#include <fstream>

#include <fmt/format.h>

#include "tessera/core/output_file.h"
#include "tessera/map_export/map_files.h"

namespace tessera::map_export {

namespace {

void writeMtl(const MapModel& model, const std::filesystem::path& path) {
  std::ofstream out = core::createOutputFile(path);
  out << "# tessera map materials: one per texture image\n";
  for (const MapMaterial& material : model.materials) {
    out << fmt::format("newmtl {}\nKa 1 1 1\nKd {:.3f} {:.3f} {:.3f}\nKs 0 0 0\nillum 1\n",
                       material.name, material.colour.x(), material.colour.y(),
                       material.colour.z());
    if (!material.image.empty()) {
      // A pattern tile repeats (MTL's default); any other image stops at its edges.
      const char* wrap = material.repeat ? "" : "-clamp on ";
      out << fmt::format("map_Kd {0}{1}\nmap_d {0}{1}\n", wrap, material.image);
    }
    out << '\n';
  }
  core::finishOutputFile(out, path);
}

}  // namespace

void writeMapObj(const MapModel& model, const std::filesystem::path& obj_path) {
  std::filesystem::path mtl_path = obj_path;
  mtl_path.replace_extension(".mtl");
  writeMtl(model, mtl_path);
  std::ofstream out = core::createOutputFile(obj_path);
  out << "# tessera map: planar patches textured from the texture database, overlays, and the "
         "non-planar residual\n";
  out << "mtllib " << mtl_path.filename().string() << '\n';
  // OBJ indices count from 1 through the whole file, positions and texture coordinates apart.
  std::size_t positions = 0, uvs = 0;
  for (const MapObject& object : model.objects) {
    out << "o " << object.name << '\n';
    if (object.material) out << "usemtl " << model.materials[*object.material].name << '\n';
    const bool coloured = object.colours.size() == object.positions.size();
    for (std::size_t i = 0; i < object.positions.size(); ++i) {
      const Eigen::Vector3d& X = object.positions[i];
      out << fmt::format("v {:.4f} {:.4f} {:.4f}", X.x(), X.y(), X.z());
      if (coloured) {
        const Eigen::Vector3d& c = object.colours[i];
        out << fmt::format(" {:.3f} {:.3f} {:.3f}", c.x(), c.y(), c.z());
      }
      out << '\n';
    }
    for (const Eigen::Vector2d& st : object.uvs)
      out << fmt::format("vt {:.6f} {:.6f}\n", st.x(), st.y());
    const bool textured = object.uvs.size() == object.positions.size();
    for (const auto& t : object.triangles) {
      if (textured) {
        out << fmt::format("f {0}/{3} {1}/{4} {2}/{5}\n", positions + t[0] + 1,
                           positions + t[1] + 1, positions + t[2] + 1, uvs + t[0] + 1,
                           uvs + t[1] + 1, uvs + t[2] + 1);
      } else {
        out << fmt::format("f {} {} {}\n", positions + t[0] + 1, positions + t[1] + 1,
                           positions + t[2] + 1);
      }
    }
    positions += object.positions.size();
    uvs += object.uvs.size();
  }
  core::finishOutputFile(out, obj_path);
}

}  // namespace tessera::map_export
