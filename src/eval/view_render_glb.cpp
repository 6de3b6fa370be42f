// map.glb for the view evaluation: its textured triangles as a RenderMesh, read with tinygltf.
#include <cstring>
#include <optional>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <tiny_gltf.h>
#include <opencv2/core.hpp>

#include "tessera/core/error.h"
#include "tessera/eval/view_render.h"

namespace tessera::eval {

namespace {

// Element `i` of an accessor of `components` floats (or unsigned indices) per element.
class AccessorReader {
 public:
  AccessorReader(const tinygltf::Model& model, int accessor_index, const std::string& file)
      : accessor_(model.accessors.at(static_cast<std::size_t>(accessor_index))) {
    const tinygltf::BufferView& view =
        model.bufferViews.at(static_cast<std::size_t>(accessor_.bufferView));
    const tinygltf::Buffer& buffer = model.buffers.at(static_cast<std::size_t>(view.buffer));
    const int size =
        tinygltf::GetComponentSizeInBytes(static_cast<std::uint32_t>(accessor_.componentType)) *
        tinygltf::GetNumComponentsInType(static_cast<std::uint32_t>(accessor_.type));
    stride_ = view.byteStride > 0 ? view.byteStride : static_cast<std::size_t>(size);
    data_ = buffer.data.data() + view.byteOffset + accessor_.byteOffset;
    if (size <= 0 || view.byteOffset + accessor_.byteOffset +
                             (accessor_.count > 0 ? (accessor_.count - 1) * stride_ + size : 0) >
                         buffer.data.size()) {
      throw core::Error(
          fmt::format("{}: accessor {} reaches past its buffer", file, accessor_index));
    }
  }
  std::size_t count() const { return accessor_.count; }
  float floatAt(std::size_t i, int component) const {
    float value = 0.0F;
    std::memcpy(&value, data_ + i * stride_ + 4 * static_cast<std::size_t>(component), 4);
    return value;
  }
  std::uint32_t indexAt(std::size_t i) const {
    const std::uint8_t* at = data_ + i * stride_;
    switch (accessor_.componentType) {
      case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
        return *at;
      case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: {
        std::uint16_t v = 0;
        std::memcpy(&v, at, 2);
        return v;
      }
      default: {
        std::uint32_t v = 0;
        std::memcpy(&v, at, 4);
        return v;
      }
    }
  }
  bool isFloat() const { return accessor_.componentType == TINYGLTF_COMPONENT_TYPE_FLOAT; }

 private:
  const tinygltf::Accessor& accessor_;
  std::size_t stride_ = 0;
  const std::uint8_t* data_ = nullptr;
};

// A material's base colour texture as RGBA, with its wrap mode; none without one.
std::optional<TextureImage> baseColourTexture(const tinygltf::Model& model,
                                              const tinygltf::Material& material) {
  const int t = material.pbrMetallicRoughness.baseColorTexture.index;
  if (t < 0) return std::nullopt;
  const tinygltf::Texture& texture = model.textures.at(static_cast<std::size_t>(t));
  const tinygltf::Image& image = model.images.at(static_cast<std::size_t>(texture.source));
  if (image.bits != 8 || (image.component != 3 && image.component != 4) || image.width <= 0) {
    return std::nullopt;
  }
  const cv::Mat pixels(image.height, image.width, CV_8UC(image.component),
                       const_cast<unsigned char*>(image.image.data()));
  TextureImage out;
  if (image.component == 4) {
    out.rgba = pixels.clone();
  } else {
    cv::Mat alpha(pixels.size(), CV_8UC1, cv::Scalar(255));
    cv::merge(std::vector<cv::Mat>{pixels, alpha}, out.rgba);
  }
  out.repeat =
      texture.sampler < 0 || model.samplers.at(static_cast<std::size_t>(texture.sampler)).wrapS ==
                                 TINYGLTF_TEXTURE_WRAP_REPEAT;
  return out;
}

}  // namespace

RenderMesh readTexturedGlb(const std::filesystem::path& path) {
  const std::string file = path.string();
  tinygltf::Model model;
  tinygltf::TinyGLTF loader;
  std::string error, warning;
  if (!std::filesystem::is_regular_file(path) ||
      !loader.LoadBinaryFromFile(&model, &error, &warning, file)) {
    throw core::Error(fmt::format("{}: cannot be read as binary glTF{}", file,
                                  error.empty() ? "" : ": " + error));
  }
  RenderMesh mesh;
  std::vector<int> texture_of_material;
  for (const tinygltf::Material& material : model.materials) {
    std::optional<TextureImage> texture = baseColourTexture(model, material);
    texture_of_material.push_back(texture ? static_cast<int>(mesh.textures.size()) : -1);
    if (texture) mesh.textures.push_back(std::move(*texture));
  }
  try {
    for (const tinygltf::Node& node : model.nodes) {
      if (node.mesh < 0) continue;
      if (!node.matrix.empty() || !node.translation.empty() || !node.rotation.empty() ||
          !node.scale.empty()) {
        throw core::Error(
            fmt::format("node '{}' has a transform (tessera writes none)", node.name));
      }
      const auto surface = static_cast<int>(mesh.surfaces.size());
      mesh.surfaces.push_back(!node.name.empty()
                                  ? node.name
                                  : model.meshes.at(static_cast<std::size_t>(node.mesh)).name);
      for (const tinygltf::Primitive& primitive :
           model.meshes.at(static_cast<std::size_t>(node.mesh)).primitives) {
        const int texture =
            primitive.material >= 0 &&
                    static_cast<std::size_t>(primitive.material) < texture_of_material.size()
                ? texture_of_material[static_cast<std::size_t>(primitive.material)]
                : -1;
        const auto position = primitive.attributes.find("POSITION");
        const auto st = primitive.attributes.find("TEXCOORD_0");
        // Untextured objects (the vertex-coloured residual) are not drawn, as in the OBJ.
        if (texture < 0 || primitive.mode != TINYGLTF_MODE_TRIANGLES || primitive.indices < 0 ||
            position == primitive.attributes.end() || st == primitive.attributes.end()) {
          continue;
        }
        const AccessorReader positions(model, position->second, file);
        const AccessorReader coordinates(model, st->second, file);
        const AccessorReader indices(model, primitive.indices, file);
        if (!positions.isFloat() || !coordinates.isFloat() ||
            coordinates.count() != positions.count()) {
          throw core::Error("a primitive's positions or texture coordinates are not float vectors");
        }
        const auto first = static_cast<int>(mesh.vertices.size());
        for (std::size_t i = 0; i < positions.count(); ++i) {
          mesh.vertices.emplace_back(positions.floatAt(i, 0), positions.floatAt(i, 1),
                                     positions.floatAt(i, 2));
        }
        for (std::size_t i = 0; i + 2 < indices.count(); i += 3) {
          Eigen::Vector3i triangle;
          for (int j = 0; j < 3; ++j) {
            const std::uint32_t v = indices.indexAt(i + static_cast<std::size_t>(j));
            if (v >= positions.count()) throw core::Error("an index is past its vertices");
            triangle[j] = first + static_cast<int>(v);
            // glTF's t runs down the image, OBJ's (which the renderer takes) up.
            mesh.uvs.emplace_back(coordinates.floatAt(v, 0), 1.0F - coordinates.floatAt(v, 1));
          }
          mesh.triangles.push_back(triangle);
          mesh.texture_of.push_back(texture);
          mesh.surface_of.push_back(surface);
        }
      }
    }
  } catch (const std::out_of_range&) {
    throw core::Error(
        fmt::format("{}: refers to an accessor, view or image it does not have", file));
  } catch (const core::Error& e) {
    throw core::Error(fmt::format("{}: {}", file, e.what()));
  }
  return mesh;
}

RenderMesh readTexturedMap(const std::filesystem::path& path) {
  return path.extension() == ".glb" ? readTexturedGlb(path) : readTexturedObj(path);
}

}  // namespace tessera::eval
