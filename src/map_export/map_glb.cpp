// map.glb: binary glTF 2.0 through tinygltf, the images embedded in the binary buffer.
#include <cstring>
#include <fstream>
#include <iterator>

#include <fmt/format.h>
#include <tiny_gltf.h>

#include "tessera/core/error.h"
#include "tessera/map_export/map_files.h"

namespace tessera::map_export {

namespace {

// glTF's numeric constants (the specification's, spelled out).
constexpr int kFloat = TINYGLTF_COMPONENT_TYPE_FLOAT;
constexpr int kUnsignedInt = TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT;
constexpr int kArrayBuffer = TINYGLTF_TARGET_ARRAY_BUFFER;
constexpr int kElementArrayBuffer = TINYGLTF_TARGET_ELEMENT_ARRAY_BUFFER;

// Appends views and accessors to the model's one buffer.
class BufferWriter {
 public:
  explicit BufferWriter(tinygltf::Model& model) : model_(model) { model_.buffers.resize(1); }

  int view(const void* data, std::size_t bytes, int target) {
    std::vector<unsigned char>& buffer = model_.buffers[0].data;
    buffer.resize((buffer.size() + 3) / 4 * 4, 0);  // every view starts 4-byte aligned
    tinygltf::BufferView view;
    view.buffer = 0;
    view.byteOffset = buffer.size();
    view.byteLength = bytes;
    view.target = target;
    const auto* bytes_in = static_cast<const unsigned char*>(data);
    buffer.insert(buffer.end(), bytes_in, bytes_in + bytes);
    model_.bufferViews.push_back(view);
    return static_cast<int>(model_.bufferViews.size()) - 1;
  }

  int accessor(const std::vector<float>& values, int components, int type,
               bool with_bounds = false) {
    tinygltf::Accessor accessor;
    accessor.bufferView = view(values.data(), values.size() * sizeof(float), kArrayBuffer);
    accessor.componentType = kFloat;
    accessor.count = values.size() / static_cast<std::size_t>(components);
    accessor.type = type;
    if (with_bounds) {  // required for POSITION
      accessor.minValues.assign(static_cast<std::size_t>(components), 1e300);
      accessor.maxValues.assign(static_cast<std::size_t>(components), -1e300);
      for (std::size_t i = 0; i < values.size(); ++i) {
        const std::size_t c = i % static_cast<std::size_t>(components);
        accessor.minValues[c] = std::min(accessor.minValues[c], double{values[i]});
        accessor.maxValues[c] = std::max(accessor.maxValues[c], double{values[i]});
      }
    }
    model_.accessors.push_back(accessor);
    return static_cast<int>(model_.accessors.size()) - 1;
  }

  int indices(const std::vector<std::array<std::uint32_t, 3>>& triangles) {
    tinygltf::Accessor accessor;
    accessor.bufferView =
        view(triangles.data(), triangles.size() * sizeof(triangles[0]), kElementArrayBuffer);
    accessor.componentType = kUnsignedInt;
    accessor.count = 3 * triangles.size();
    accessor.type = TINYGLTF_TYPE_SCALAR;
    model_.accessors.push_back(accessor);
    return static_cast<int>(model_.accessors.size()) - 1;
  }

 private:
  tinygltf::Model& model_;
};

std::vector<unsigned char> readFile(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw core::Error(fmt::format("{}: cannot be read for map.glb", path.string()));
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// One glTF material per map material; an image becomes an embedded PNG with its sampler.
void addMaterials(const MapModel& map, const std::filesystem::path& images_dir,
                  tinygltf::Model& model, BufferWriter& buffer) {
  for (const MapMaterial& material : map.materials) {
    tinygltf::Material out;
    out.name = material.name;
    out.doubleSided = true;
    out.pbrMetallicRoughness.metallicFactor = 0.0;
    out.pbrMetallicRoughness.roughnessFactor = 1.0;
    if (material.image.empty()) {
      out.pbrMetallicRoughness.baseColorFactor = {material.colour.x(), material.colour.y(),
                                                  material.colour.z(), 1.0};
    } else {
      const std::vector<unsigned char> png = readFile(images_dir / material.image);
      tinygltf::Image image;
      image.name = material.image;
      image.mimeType = "image/png";
      // Target 0: image data is neither a vertex nor an index buffer.
      image.bufferView = buffer.view(png.data(), png.size(), 0);
      model.images.push_back(image);
      tinygltf::Sampler sampler;
      sampler.magFilter = TINYGLTF_TEXTURE_FILTER_LINEAR;
      sampler.minFilter = TINYGLTF_TEXTURE_FILTER_LINEAR;
      const int wrap =
          material.repeat ? TINYGLTF_TEXTURE_WRAP_REPEAT : TINYGLTF_TEXTURE_WRAP_CLAMP_TO_EDGE;
      sampler.wrapS = wrap;
      sampler.wrapT = wrap;
      model.samplers.push_back(sampler);
      tinygltf::Texture texture;
      texture.source = static_cast<int>(model.images.size()) - 1;
      texture.sampler = static_cast<int>(model.samplers.size()) - 1;
      model.textures.push_back(texture);
      out.pbrMetallicRoughness.baseColorTexture.index = static_cast<int>(model.textures.size()) - 1;
      out.alphaMode = "MASK";  // texels never observed are transparent
      out.alphaCutoff = 0.5;
    }
    model.materials.push_back(out);
  }
}

}  // namespace

void writeMapGlb(const MapModel& map, const std::filesystem::path& images_dir,
                 const std::filesystem::path& glb_path) {
  tinygltf::Model model;
  model.asset.version = "2.0";
  model.asset.generator = "tessera";
  BufferWriter buffer(model);
  addMaterials(map, images_dir, model, buffer);
  tinygltf::Scene scene;
  for (const MapObject& object : map.objects) {
    std::vector<float> positions;
    for (const Eigen::Vector3d& X : object.positions) {
      positions.insert(positions.end(), {static_cast<float>(X.x()), static_cast<float>(X.y()),
                                         static_cast<float>(X.z())});
    }
    tinygltf::Primitive primitive;
    primitive.mode = TINYGLTF_MODE_TRIANGLES;
    primitive.attributes["POSITION"] = buffer.accessor(positions, 3, TINYGLTF_TYPE_VEC3, true);
    if (object.uvs.size() == object.positions.size()) {
      std::vector<float> uvs;
      // glTF's t axis points down the image, OBJ's up.
      for (const Eigen::Vector2d& st : object.uvs) {
        uvs.insert(uvs.end(), {static_cast<float>(st.x()), static_cast<float>(1.0 - st.y())});
      }
      primitive.attributes["TEXCOORD_0"] = buffer.accessor(uvs, 2, TINYGLTF_TYPE_VEC2);
    }
    if (object.colours.size() == object.positions.size()) {
      std::vector<float> colours;
      for (const Eigen::Vector3d& c : object.colours) {
        colours.insert(colours.end(), {static_cast<float>(c.x()), static_cast<float>(c.y()),
                                       static_cast<float>(c.z())});
      }
      primitive.attributes["COLOR_0"] = buffer.accessor(colours, 3, TINYGLTF_TYPE_VEC3);
    }
    primitive.indices = buffer.indices(object.triangles);
    if (object.material) primitive.material = static_cast<int>(*object.material);
    tinygltf::Mesh mesh;
    mesh.name = object.name;
    mesh.primitives.push_back(primitive);
    model.meshes.push_back(mesh);
    tinygltf::Node node;
    node.name = object.name;
    node.mesh = static_cast<int>(model.meshes.size()) - 1;
    model.nodes.push_back(node);
    scene.nodes.push_back(static_cast<int>(model.nodes.size()) - 1);
  }
  model.scenes.push_back(scene);
  model.defaultScene = 0;

  tinygltf::TinyGLTF writer;
  if (!writer.WriteGltfSceneToFile(&model, glb_path.string(), true, true, false, true)) {
    throw core::Error(fmt::format("{}: could not write (disk full?)", glb_path.string()));
  }
}

}  // namespace tessera::map_export
