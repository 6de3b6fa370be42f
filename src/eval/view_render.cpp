#include "tessera/eval/view_render.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <map>

#include <fmt/format.h>
#include <tiny_obj_loader.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "tessera/core/error.h"
#include "tessera/fusion/mesh_colours.h"

namespace tessera::eval {

namespace {

// A triangle corner in camera coordinates with what is interpolated across the triangle:
// (s, t, unused) for textured meshes, RGB for vertex-coloured ones.
struct Corner {
  Eigen::Vector3f X_C;
  Eigen::Vector3f attribute;
};

// Sutherland-Hodgman clipping of a triangle against the plane z = near: at most 4 corners.
int clipNear(const std::array<Corner, 3>& in, float near, std::array<Corner, 4>& out) {
  int n = 0;
  for (int i = 0; i < 3; ++i) {
    const Corner& a = in[static_cast<std::size_t>(i)];
    const Corner& b = in[static_cast<std::size_t>((i + 1) % 3)];
    const bool a_in = a.X_C.z() >= near, b_in = b.X_C.z() >= near;
    if (a_in) out[static_cast<std::size_t>(n++)] = a;
    if (a_in != b_in) {
      const float f = (near - a.X_C.z()) / (b.X_C.z() - a.X_C.z());
      out[static_cast<std::size_t>(n++)] = {a.X_C + f * (b.X_C - a.X_C),
                                            a.attribute + f * (b.attribute - a.attribute)};
    }
  }
  return n;
}

// Texel index i of an axis of n texels: clamped to the edge, or wrapped (a repeating texture).
int texelIndex(int i, int n, bool repeat) {
  if (!repeat) return std::clamp(i, 0, n - 1);
  const int r = i % n;
  return r < 0 ? r + n : r;
}

// Bilinear RGB of an RGBA texture at (s, t) over its opaque texels; false where the nearest
// texel is transparent (an empty texel covers nothing). A repeating texture (a pattern tile,
// MTL's default) wraps at its edges; a clamped one (`-clamp on`) stops there.
bool sampleTexture(const TextureImage& texture, float s, float t, Eigen::Vector3f& rgb) {
  const cv::Mat& image = texture.rgba;
  const bool repeat = texture.repeat;
  if (repeat) s -= std::floor(s), t -= std::floor(t);
  // OBJ's t axis points up: the image's first row is t = 1.
  const float x = s * static_cast<float>(image.cols) - 0.5F;
  const float y = (1.0F - t) * static_cast<float>(image.rows) - 0.5F;
  const int nx = texelIndex(static_cast<int>(std::lround(x)), image.cols, repeat);
  const int ny = texelIndex(static_cast<int>(std::lround(y)), image.rows, repeat);
  if (image.at<cv::Vec4b>(ny, nx)[3] == 0) return false;
  const int x0 = static_cast<int>(std::floor(x)), y0 = static_cast<int>(std::floor(y));
  const float fx = x - static_cast<float>(x0), fy = y - static_cast<float>(y0);
  Eigen::Vector3f sum = Eigen::Vector3f::Zero();
  float total = 0.0F;
  for (int dy = 0; dy < 2; ++dy) {
    for (int dx = 0; dx < 2; ++dx) {
      const int cx = texelIndex(x0 + dx, image.cols, repeat);
      const int cy = texelIndex(y0 + dy, image.rows, repeat);
      const cv::Vec4b& texel = image.at<cv::Vec4b>(cy, cx);
      if (texel[3] == 0) continue;
      const float w = (dx != 0 ? fx : 1.0F - fx) * (dy != 0 ? fy : 1.0F - fy);
      sum += w * Eigen::Vector3f(texel[0], texel[1], texel[2]);
      total += w;
    }
  }
  if (total <= 0.0F) {
    const cv::Vec4b& texel = image.at<cv::Vec4b>(ny, nx);
    rgb = Eigen::Vector3f(texel[0], texel[1], texel[2]);
  } else {
    rgb = sum / total;
  }
  return true;
}

class Rasteriser {
 public:
  Rasteriser(const core::Intrinsics& k, ViewImage& view) : k_(k), view_(view) {}

  // Draws one convex polygon (a clipped triangle) as a fan.
  void drawPolygon(const std::array<Corner, 4>& corners, int n, const TextureImage* texture,
                   int surface) {
    for (int i = 1; i + 1 < n; ++i) {
      drawTriangle({corners[0], corners[static_cast<std::size_t>(i)],
                    corners[static_cast<std::size_t>(i + 1)]},
                   texture, surface);
    }
  }

 private:
  void drawTriangle(const std::array<Corner, 3>& c, const TextureImage* texture, int surface) {
    // In double precision: a wall's long quads, clipped at the near plane, project far off
    // the image, and float barycentrics then lose the millimetre that keeps an overlay in
    // front of its wall.
    std::array<Eigen::Vector2d, 3> p;
    for (std::size_t i = 0; i < 3; ++i) {
      const Eigen::Vector3d X = c[i].X_C.cast<double>();
      p[i] = {k_.fx * X.x() / X.z() + k_.cx, k_.fy * X.y() / X.z() + k_.cy};
    }
    const double area = edge(p[0], p[1], p[2]);
    if (std::abs(area) < 1e-12) return;
    const int x_min =
        std::max(0, static_cast<int>(std::ceil(std::min({p[0].x(), p[1].x(), p[2].x()}))));
    const int x_max = std::min(
        view_.rgb.cols - 1, static_cast<int>(std::floor(std::max({p[0].x(), p[1].x(), p[2].x()}))));
    const int y_min =
        std::max(0, static_cast<int>(std::ceil(std::min({p[0].y(), p[1].y(), p[2].y()}))));
    const int y_max = std::min(
        view_.rgb.rows - 1, static_cast<int>(std::floor(std::max({p[0].y(), p[1].y(), p[2].y()}))));
    const std::array<double, 3> inverse_z = {1.0 / c[0].X_C.z(), 1.0 / c[1].X_C.z(),
                                             1.0 / c[2].X_C.z()};
    for (int y = y_min; y <= y_max; ++y) {
      auto* depth = view_.depth.ptr<float>(y);
      auto* rgb = view_.rgb.ptr<cv::Vec3b>(y);
      auto* surface_at = view_.surface.ptr<int>(y);
      for (int x = x_min; x <= x_max; ++x) {
        const Eigen::Vector2d q(x, y);
        // Barycentric coordinates from the signed edge functions (either winding).
        const double b0 = edge(p[1], p[2], q) / area;
        const double b1 = edge(p[2], p[0], q) / area;
        const double b2 = 1.0 - b0 - b1;
        if (b0 < 0.0 || b1 < 0.0 || b2 < 0.0) continue;
        // Perspective-correct interpolation: attributes / z are linear in screen space.
        const double w0 = b0 * inverse_z[0], w1 = b1 * inverse_z[1], w2 = b2 * inverse_z[2];
        const auto z = static_cast<float>(1.0 / (w0 + w1 + w2));
        if (depth[x] > 0.0F && depth[x] <= z) continue;
        const Eigen::Vector3f attribute =
            (static_cast<double>(z) *
             (w0 * c[0].attribute.cast<double>() + w1 * c[1].attribute.cast<double>() +
              w2 * c[2].attribute.cast<double>()))
                .cast<float>();
        Eigen::Vector3f colour = attribute;
        if (texture != nullptr && !sampleTexture(*texture, attribute.x(), attribute.y(), colour)) {
          continue;
        }
        depth[x] = z;
        surface_at[x] = surface;
        for (int ch = 0; ch < 3; ++ch) {
          rgb[x][ch] = cv::saturate_cast<std::uint8_t>(colour[ch]);
        }
      }
    }
  }

  static double edge(const Eigen::Vector2d& a, const Eigen::Vector2d& b, const Eigen::Vector2d& q) {
    return (b.x() - a.x()) * (q.y() - a.y()) - (b.y() - a.y()) * (q.x() - a.x());
  }

  const core::Intrinsics& k_;
  ViewImage& view_;
};

// The material's image as RGBA (opaque when the file has no alpha channel).
cv::Mat readTextureImage(const std::filesystem::path& path) {
  const cv::Mat image = cv::imread(path.string(), cv::IMREAD_UNCHANGED);
  if (image.empty()) throw core::Error(fmt::format("{}: missing or not an image", path.string()));
  cv::Mat rgba;
  if (image.channels() == 4) {
    cv::cvtColor(image, rgba, cv::COLOR_BGRA2RGBA);
  } else if (image.channels() == 3) {
    cv::cvtColor(image, rgba, cv::COLOR_BGR2RGBA);
  } else {
    cv::cvtColor(image, rgba, cv::COLOR_GRAY2RGBA);
  }
  if (rgba.depth() != CV_8U) rgba.convertTo(rgba, CV_8U, 1.0 / 257.0);
  return rgba;
}

}  // namespace

RenderMesh readTexturedObj(const std::filesystem::path& path) {
  tinyobj::ObjReaderConfig config;
  config.triangulate = true;
  config.vertex_color = false;
  config.mtl_search_path = path.parent_path().string();
  tinyobj::ObjReader reader;
  if (!std::filesystem::is_regular_file(path) || !reader.ParseFromFile(path.string(), config)) {
    throw core::Error(fmt::format("{}: cannot be read as OBJ{}", path.string(),
                                  reader.Error().empty() ? "" : ": " + reader.Error()));
  }
  const tinyobj::attrib_t& attrib = reader.GetAttrib();
  RenderMesh mesh;
  for (std::size_t i = 0; i + 2 < attrib.vertices.size(); i += 3) {
    mesh.vertices.emplace_back(attrib.vertices[i], attrib.vertices[i + 1], attrib.vertices[i + 2]);
  }
  // One texture per material that names an image; the same image is loaded once.
  std::vector<int> texture_of_material;
  std::map<std::string, int> loaded;
  for (const tinyobj::material_t& material : reader.GetMaterials()) {
    if (material.diffuse_texname.empty()) {
      texture_of_material.push_back(-1);
      continue;
    }
    auto [it, inserted] =
        loaded.try_emplace(material.diffuse_texname, static_cast<int>(mesh.textures.size()));
    if (inserted) {
      mesh.textures.push_back({readTextureImage(path.parent_path() / material.diffuse_texname),
                               !material.diffuse_texopt.clamp});
    }
    texture_of_material.push_back(it->second);
  }
  for (const tinyobj::shape_t& shape : reader.GetShapes()) {
    const auto surface = static_cast<int>(mesh.surfaces.size());
    mesh.surfaces.push_back(shape.name);
    const auto& indices = shape.mesh.indices;
    for (std::size_t f = 0; f < shape.mesh.num_face_vertices.size(); ++f) {
      const std::size_t first = 3 * f;
      if (first + 2 >= indices.size()) break;  // triangulated: three corners a face
      const int material = shape.mesh.material_ids[f];
      const int texture = material >= 0 && material < static_cast<int>(texture_of_material.size())
                              ? texture_of_material[static_cast<std::size_t>(material)]
                              : -1;
      Eigen::Vector3i triangle;
      for (int j = 0; j < 3; ++j) {
        const tinyobj::index_t& index = indices[first + static_cast<std::size_t>(j)];
        triangle[j] = index.vertex_index;
        const int tc = index.texcoord_index;
        mesh.uvs.emplace_back(
            tc >= 0 ? attrib.texcoords[2 * static_cast<std::size_t>(tc)] : 0.0F,
            tc >= 0 ? attrib.texcoords[2 * static_cast<std::size_t>(tc) + 1] : 0.0F);
      }
      mesh.triangles.push_back(triangle);
      mesh.texture_of.push_back(texture);
      mesh.surface_of.push_back(surface);
    }
  }
  return mesh;
}

RenderMesh readColouredPly(const std::filesystem::path& path) {
  const fusion::SurfaceMesh surface = fusion::readPly(path);
  RenderMesh mesh;
  mesh.vertices.reserve(surface.vertices.size());
  mesh.colours.reserve(surface.vertices.size());
  for (std::size_t i = 0; i < surface.vertices.size(); ++i) {
    mesh.vertices.push_back(surface.vertices[i].cast<float>());
    mesh.colours.push_back((255.0 * surface.colors[i]).cast<float>());
  }
  mesh.triangles = surface.triangles;
  return mesh;
}

ViewImage renderView(const RenderMesh& mesh, const core::Intrinsics& intrinsics,
                     const core::Isometry& T_W_C, double near_m) {
  ViewImage view;
  view.rgb = cv::Mat::zeros(intrinsics.height, intrinsics.width, CV_8UC3);
  view.depth = cv::Mat::zeros(intrinsics.height, intrinsics.width, CV_32F);
  view.surface = cv::Mat(intrinsics.height, intrinsics.width, CV_32S, cv::Scalar(-1));
  const Eigen::Affine3f T_C_W = T_W_C.inverse().cast<float>();
  std::vector<Eigen::Vector3f> vertices_C(mesh.vertices.size());
  for (std::size_t i = 0; i < mesh.vertices.size(); ++i) vertices_C[i] = T_C_W * mesh.vertices[i];
  Rasteriser rasteriser(intrinsics, view);
  const auto near = static_cast<float>(near_m);
  std::array<Corner, 4> clipped;
  for (std::size_t f = 0; f < mesh.triangles.size(); ++f) {
    const TextureImage* texture = nullptr;
    const int surface = f < mesh.surface_of.size() ? mesh.surface_of[f] : -1;
    if (mesh.textured()) {
      if (mesh.texture_of[f] < 0) continue;  // no image: the patch is not textured
      texture = &mesh.textures[static_cast<std::size_t>(mesh.texture_of[f])];
    }
    std::array<Corner, 3> corners;
    bool any_in_front = false;
    for (std::size_t j = 0; j < 3; ++j) {
      const auto v = static_cast<std::size_t>(mesh.triangles[f][static_cast<Eigen::Index>(j)]);
      corners[j].X_C = vertices_C[v];
      if (texture != nullptr) {
        const Eigen::Vector2f& st = mesh.uvs[3 * f + j];
        corners[j].attribute = {st.x(), st.y(), 0.0F};
      } else {
        corners[j].attribute = mesh.colours[v];
      }
      any_in_front = any_in_front || vertices_C[v].z() >= near;
    }
    if (!any_in_front) continue;
    rasteriser.drawPolygon(clipped, clipNear(corners, near, clipped), texture, surface);
  }
  return view;
}

}  // namespace tessera::eval
