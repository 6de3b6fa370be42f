// The map as users open it: outlines triangulated with their holes, and the office's map.obj and
// map.glb loaded back with real loaders (tinyobjloader, tinygltf).
#include <algorithm>
#include <cmath>
#include <fstream>
#include <iterator>
#include <map>
#include <set>

#include <gtest/gtest.h>
#include <tiny_gltf.h>
#include <tiny_obj_loader.h>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include "support/synthetic_plane.h"
#include "support/test_data.h"
#include "tessera/core/trajectory.h"
#include "tessera/drivers/oni/oni_source.h"
#include "tessera/eval/view_render.h"
#include "tessera/map_export/map_model.h"
#include "tessera/pipeline/run.h"

namespace tessera::map_export {
namespace {

namespace fs = std::filesystem;

double triangleArea(const Eigen::Vector2d& a, const Eigen::Vector2d& b, const Eigen::Vector2d& c) {
  const Eigen::Vector2d u = b - a, v = c - a;
  return 0.5 * (u.x() * v.y() - u.y() * v.x());
}

bool inside(const Eigen::Vector2d& p, double x0, double y0, double x1, double y1) {
  return p.x() > x0 && p.x() < x1 && p.y() > y0 && p.y() < y1;
}

planes::Polygon2 box(double x0, double y0, double x1, double y1) {
  return {{x0, y0}, {x1, y0}, {x1, y1}, {x0, y1}};
}

// A 2 x 1 m wall with two windows: the triangles cover the wall less the windows exactly,
// counter-clockwise, and none lies in a window.
TEST(TriangulatePolygon, AWallWithTwoWindowsCoversItsAreaAndNotTheWindows) {
  planes::OutlinePart wall{box(0, 0, 2, 1), {box(0.2, 0.3, 0.6, 0.7), box(1.2, 0.2, 1.8, 0.5)}};
  const PlanarTriangles t = triangulatePolygon(wall);
  ASSERT_FALSE(t.triangles.empty());
  double area = 0.0;
  for (const auto& tri : t.triangles) {
    const Eigen::Vector2d &a = t.vertices[tri[0]], &b = t.vertices[tri[1]], &c = t.vertices[tri[2]];
    const double signed_area = triangleArea(a, b, c);
    EXPECT_GT(signed_area, 0.0);
    area += signed_area;
    const Eigen::Vector2d centroid = (a + b + c) / 3.0;
    EXPECT_FALSE(inside(centroid, 0.2, 0.3, 0.6, 0.7));
    EXPECT_FALSE(inside(centroid, 1.2, 0.2, 1.8, 0.5));
    EXPECT_TRUE(inside(centroid, 0, 0, 2, 1));
  }
  EXPECT_NEAR(area, 2.0 - 0.16 - 0.18, 1e-9);
  EXPECT_EQ(t.vertices.size(), 12u);  // the corners only: no point added
}

// An L-shaped (concave) floor, given clockwise: only the L is covered.
TEST(TriangulatePolygon, AConcaveOutlineInEitherOrientation) {
  planes::OutlinePart floor{{{0, 0}, {0, 2}, {1, 2}, {1, 1}, {2, 1}, {2, 0}}, {}};
  const PlanarTriangles t = triangulatePolygon(floor);
  double area = 0.0;
  for (const auto& tri : t.triangles) {
    const Eigen::Vector2d centroid =
        (t.vertices[tri[0]] + t.vertices[tri[1]] + t.vertices[tri[2]]) / 3.0;
    EXPECT_FALSE(inside(centroid, 1, 1, 2, 2));
    area += triangleArea(t.vertices[tri[0]], t.vertices[tri[1]], t.vertices[tri[2]]);
  }
  EXPECT_NEAR(area, 3.0, 1e-9);
}

TEST(TriangulatePolygon, ADegenerateOutlineGivesNothing) {
  EXPECT_TRUE(triangulatePolygon({{{0, 0}, {1, 1}}, {}}).triangles.empty());
  EXPECT_TRUE(triangulatePolygon({{{0, 0}, {1, 0}, {2, 0}}, {}}).triangles.empty());
}

pipeline::RunSummary runInto(const fs::path& recording, const fs::path& out) {
  drivers::oni::OniSource source(recording);
  pipeline::RunOptions options;
  options.out_dir = out;
  options.poses = pipeline::PoseSource::kGroundTruth;
  options.residual = true;
  return pipeline::runPipeline(source, pipeline::loadRunConfig(std::nullopt), options);
}

// map.glb as tinygltf reads it back: one mesh per object, and its triangle count.
std::size_t glbTriangles(const fs::path& path, std::size_t& meshes) {
  tinygltf::Model model;
  tinygltf::TinyGLTF loader;
  std::string error, warning;
  EXPECT_TRUE(loader.LoadBinaryFromFile(&model, &error, &warning, path.string())) << error;
  meshes = model.meshes.size();
  std::size_t indices = 0;
  for (const tinygltf::Mesh& mesh : model.meshes) {
    for (const tinygltf::Primitive& primitive : mesh.primitives) {
      indices += model.accessors.at(static_cast<std::size_t>(primitive.indices)).count;
    }
  }
  return indices / 3;
}

// A short real sequence (the committed TUM excerpt): both files load back with the same
// objects and triangles as the run counted, textures included.
TEST(MapExport, ARealSequenceMapLoadsBackInBothFormats) {
  const fs::path out = test::freshTempDir();
  const pipeline::RunSummary summary =
      runInto(test::sourceDir() / "recordings/tum_fr1_rpy_20.oni", out);
  ASSERT_GT(summary.exported.map_triangles, 0u);
  tinyobj::ObjReader obj;
  ASSERT_TRUE(obj.ParseFromFile((out / "map.obj").string())) << obj.Error();
  std::size_t triangles = 0;
  for (const tinyobj::shape_t& shape : obj.GetShapes()) {
    triangles += shape.mesh.num_face_vertices.size();
  }
  EXPECT_EQ(triangles, summary.exported.map_triangles);
  std::size_t textured = 0;
  for (const tinyobj::material_t& m : obj.GetMaterials()) textured += !m.diffuse_texname.empty();
  EXPECT_GE(textured, 1u);
  std::size_t meshes = 0;
  EXPECT_EQ(glbTriangles(out / "map.glb", meshes), summary.exported.map_triangles);
  EXPECT_EQ(meshes, obj.GetShapes().size());

  // Rendered by tessera eval's readers from three of the run's poses, the glTF shows what the
  // OBJ shows: the same pixels covered and the same colours, but for edge pixels.
  const eval::RenderMesh from_obj = eval::readTexturedMap(out / "map.obj");
  const eval::RenderMesh from_glb = eval::readTexturedMap(out / "map.glb");
  // Drawn: the textured triangles (the OBJ reader also lists the residual's, undrawn).
  const auto drawn = [](const eval::RenderMesh& mesh) {
    return std::count_if(mesh.texture_of.begin(), mesh.texture_of.end(),
                         [](int t) { return t >= 0; });
  };
  ASSERT_GT(drawn(from_obj), 0);
  ASSERT_EQ(drawn(from_glb), drawn(from_obj));
  ASSERT_EQ(from_glb.textures.size(), from_obj.textures.size());
  const core::Trajectory poses = core::readTumTrajectory(out / "trajectory.txt");
  ASSERT_GE(poses.size(), 3u);
  for (const auto& at :
       {poses.begin(), std::next(poses.begin(), static_cast<long>(poses.size() / 2)),
        std::prev(poses.end())}) {
    const eval::ViewImage a = eval::renderView(from_obj, test::kinectIntrinsics(), at->second);
    const eval::ViewImage b = eval::renderView(from_glb, test::kinectIntrinsics(), at->second);
    const cv::Mat covered_a = a.depth > 0, covered_b = b.depth > 0;
    const int covered = cv::countNonZero(covered_a);
    ASSERT_GT(covered, 10000);
    // Apart from edge pixels: the OBJ prints positions to 0.1 mm, the glTF keeps floats.
    EXPECT_LT(cv::countNonZero(covered_a != covered_b), covered / 200);
    EXPECT_GT(cv::PSNR(a.rgb, b.rgb), 38.0);
  }
}

double area3(const float* a, const float* b, const float* c) {
  const Eigen::Vector3d A(a[0], a[1], a[2]), B(b[0], b[1], b[2]), C(c[0], c[1], c[2]);
  return 0.5 * (B - A).cross(C - A).norm();
}

// The default recording at true poses, with the residual: map.obj loads with tinyobjloader and
// map.glb with tinygltf; both hold the same objects and triangles; patches that show the same
// database texture share its one material; pattern tiles repeat through texture coordinates
// beyond [0, 1] (REPEAT samplers in glTF) and other images clamp; the patches' triangles
// cover the patches' area; the residual is vertex-coloured.
TEST(MapExport, TheOfficeMapLoadsBackWithTinyobjloaderAndTinygltf) {
  const fs::path recording = test::sourceDir() / "recordings/office.oni";
  if (!fs::is_regular_file(recording)) GTEST_SKIP() << "recordings/office.oni not rendered";
  const fs::path out = test::freshTempDir();
  const pipeline::RunSummary summary = runInto(recording, out);

  tinyobj::ObjReaderConfig config;
  config.vertex_color = true;
  tinyobj::ObjReader obj;
  ASSERT_TRUE(obj.ParseFromFile((out / "map.obj").string(), config)) << obj.Error();
  EXPECT_TRUE(obj.Warning().empty()) << obj.Warning();
  const tinyobj::attrib_t& attrib = obj.GetAttrib();
  std::map<std::string, const tinyobj::shape_t*> shapes;
  std::size_t triangles = 0;
  for (const tinyobj::shape_t& shape : obj.GetShapes()) {
    shapes[shape.name] = &shape;
    triangles += shape.mesh.num_face_vertices.size();
  }
  EXPECT_EQ(triangles, summary.exported.map_triangles);
  std::vector<std::string> material_names;
  for (const tinyobj::material_t& m : obj.GetMaterials()) {
    material_names.push_back(m.name);
    if (!m.diffuse_texname.empty()) {
      EXPECT_TRUE(fs::is_regular_file(out / m.diffuse_texname)) << m.diffuse_texname;
    }
  }
  const auto materialOf = [&](const tinyobj::shape_t& shape) {
    return material_names.at(static_cast<std::size_t>(shape.mesh.material_ids.at(0)));
  };

  std::ifstream patches_file(out / "patches.json");
  const nlohmann::json patches = nlohmann::json::parse(patches_file);
  std::set<std::int64_t> texture_ids;
  bool saw_pattern = false;
  double patch_area = 0.0, triangle_area = 0.0;
  for (const auto& patch : patches["patches"]) {
    const std::string name = "patch_" + std::to_string(patch["id"].get<int>()) + "_v" +
                             std::to_string(patch["version"].get<int>());
    ASSERT_TRUE(shapes.count(name)) << name;
    const tinyobj::shape_t& shape = *shapes[name];
    patch_area += patch["area_m2"].get<double>();
    float s_min = 1e9F, s_max = -1e9F;
    for (std::size_t i = 0; i < shape.mesh.indices.size(); i += 3) {
      const auto at = [&](std::size_t k) {
        return &attrib
                    .vertices[3 * static_cast<std::size_t>(shape.mesh.indices[i + k].vertex_index)];
      };
      triangle_area += area3(at(0), at(1), at(2));
    }
    for (const tinyobj::index_t& index : shape.mesh.indices) {
      const float s = attrib.texcoords[2 * static_cast<std::size_t>(index.texcoord_index)];
      s_min = std::min(s_min, s);
      s_max = std::max(s_max, s);
    }
    if (patch["instance"].is_null()) continue;
    const auto& instance = patch["instance"];
    const std::int64_t id = instance["texture_id"];
    texture_ids.insert(id);
    // Every patch that shows a texture uses that texture's one material.
    EXPECT_EQ(materialOf(shape), "texture_" + std::to_string(id)) << name;
    if (instance["tiled"].get<bool>()) {
      saw_pattern = true;
      EXPECT_GT(s_max - s_min, 1.5) << name << ": a pattern tile repeats across the patch";
    }
    for (std::size_t k = 0; k < instance["overlays"].size(); ++k) {
      const std::int64_t overlay_id = instance["overlays"][k]["texture_id"];
      texture_ids.insert(overlay_id);
      const std::string overlay = name + "_overlay_" + std::to_string(k + 1);
      ASSERT_TRUE(shapes.count(overlay)) << overlay;
      EXPECT_EQ(materialOf(*shapes[overlay]), "texture_" + std::to_string(overlay_id));
      EXPECT_EQ(shapes[overlay]->mesh.num_face_vertices.size(), 2u);
    }
  }
  EXPECT_TRUE(saw_pattern);
  // The simplified outlines stay within half a cell of the occupancy grid's boundary.
  EXPECT_NEAR(triangle_area, patch_area, 0.05 * patch_area);
  std::size_t texture_materials = 0;
  for (const std::string& m : material_names) texture_materials += m.rfind("texture_", 0) == 0;
  EXPECT_EQ(texture_materials, texture_ids.size());  // one material per texture, shared

  ASSERT_TRUE(shapes.count("residual"));
  const tinyobj::shape_t& residual = *shapes["residual"];
  EXPECT_GT(residual.mesh.num_face_vertices.size(), 1000u);
  std::set<float> reds;
  for (const tinyobj::index_t& index : residual.mesh.indices) {
    reds.insert(attrib.colors[3 * static_cast<std::size_t>(index.vertex_index)]);
  }
  EXPECT_GT(reds.size(), 20u);  // coloured by the TSDF, not a constant

  tinygltf::Model model;
  tinygltf::TinyGLTF loader;
  std::string error, warning;
  ASSERT_TRUE(loader.LoadBinaryFromFile(&model, &error, &warning, (out / "map.glb").string()))
      << error;
  EXPECT_EQ(model.meshes.size(), shapes.size());
  std::size_t indices = 0;
  for (const tinygltf::Mesh& mesh : model.meshes) {
    ASSERT_EQ(mesh.primitives.size(), 1u);
    const tinygltf::Primitive& primitive = mesh.primitives[0];
    indices += model.accessors[static_cast<std::size_t>(primitive.indices)].count;
    EXPECT_EQ(primitive.attributes.count("COLOR_0"), mesh.name == "residual" ? 1u : 0u);
    EXPECT_EQ(primitive.attributes.count("TEXCOORD_0"), mesh.name == "residual" ? 0u : 1u);
    const tinygltf::Material& material =
        model.materials[static_cast<std::size_t>(primitive.material)];
    const int texture = material.pbrMetallicRoughness.baseColorTexture.index;
    if (texture < 0) continue;
    const tinygltf::Texture& t = model.textures[static_cast<std::size_t>(texture)];
    const tinygltf::Sampler& sampler = model.samplers[static_cast<std::size_t>(t.sampler)];
    const tinygltf::Image& image = model.images[static_cast<std::size_t>(t.source)];
    EXPECT_GT(image.width, 0);  // decoded from the embedded PNG
    const auto obj_material =
        std::find_if(obj.GetMaterials().begin(), obj.GetMaterials().end(),
                     [&](const tinyobj::material_t& m) { return m.name == material.name; });
    ASSERT_NE(obj_material, obj.GetMaterials().end());
    const bool repeats = !obj_material->diffuse_texopt.clamp;
    EXPECT_EQ(sampler.wrapS,
              repeats ? TINYGLTF_TEXTURE_WRAP_REPEAT : TINYGLTF_TEXTURE_WRAP_CLAMP_TO_EDGE)
        << material.name;
  }
  EXPECT_EQ(indices, 3 * triangles);
}

}  // namespace
}  // namespace tessera::map_export
