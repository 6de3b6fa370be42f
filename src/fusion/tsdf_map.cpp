#include "tessera/fusion/tsdf_map.h"

#include <fstream>
#include <optional>

#include <cstring>

#include <fmt/format.h>
#include <omp.h>
#include <open3d/camera/PinholeCameraIntrinsic.h>
#include <open3d/geometry/Image.h>
#include <open3d/geometry/RGBDImage.h>
#include <open3d/geometry/TriangleMesh.h>
#include <open3d/io/TriangleMeshIO.h>
#include <open3d/pipelines/integration/ScalableTSDFVolume.h>
#include <open3d/pipelines/integration/UniformTSDFVolume.h>
#include <opencv2/imgproc.hpp>

#include "tessera/core/error.h"

namespace tessera::fusion {

namespace o3d = open3d;

struct TsdfMap::Volume {
  o3d::pipelines::integration::ScalableTSDFVolume tsdf;
  Volume(double voxel, double trunc, int block_resolution)
      : tsdf(voxel, trunc, o3d::pipelines::integration::TSDFVolumeColorType::RGB8,
             block_resolution) {}
};

void readConfig(const core::ConfigSection& section, TsdfConfig& config) {
  section.read("voxel_size_m", config.voxel_size_m);
  section.read("truncation_m", config.truncation_m);
  section.read("min_depth_m", config.min_depth_m);
  section.read("max_depth_m", config.max_depth_m);
  section.read("block_resolution", config.block_resolution);
  section.read("integration_scale", config.integration_scale);
  section.read("integrate_every_n_frames", config.integrate_every_n_frames);
  section.read("release_distance_m", config.release_distance_m);
  section.read("correct_after_loop_closure", config.correct_after_loop_closure);
  if (config.voxel_size_m <= 0.0 || config.truncation_m < config.voxel_size_m) {
    throw core::ConfigError(
        "tsdf: voxel_size_m must be positive and truncation_m at least one voxel");
  }
  if (config.min_depth_m < 0.0 || config.max_depth_m <= config.min_depth_m) {
    throw core::ConfigError("tsdf: need 0 <= min_depth_m < max_depth_m");
  }
  if (config.block_resolution < 2) {
    throw core::ConfigError("tsdf: block_resolution must be at least 2");
  }
  if (config.integration_scale < 1 || config.integration_scale > 8) {
    throw core::ConfigError("tsdf: integration_scale must be between 1 and 8");
  }
  if (config.integrate_every_n_frames < 1) {
    throw core::ConfigError("tsdf: integrate_every_n_frames must be at least 1");
  }
  if (config.release_distance_m < 0.0) {
    throw core::ConfigError("tsdf: release_distance_m must be 0 (keep all) or positive");
  }
}

namespace {

// Depth in metres as a float image, taking every `step`-th pixel (no averaging, so depth
// never mixes across an edge), with depth outside [min, max] set to 0 (invalid).
o3d::geometry::Image depthMetres(const cv::Mat& depth_mm, int step, double min_m, double max_m) {
  o3d::geometry::Image image;
  image.Prepare(depth_mm.cols / step, depth_mm.rows / step, 1, 4);
  for (int v = 0; v < image.height_; ++v) {
    const auto* src = depth_mm.ptr<std::uint16_t>(v * step);
    auto* dst = image.PointerAt<float>(0, v);
    for (int u = 0; u < image.width_; ++u) {
      const double z = src[u * step] * 1e-3;
      dst[u] = (z >= min_m && z <= max_m) ? static_cast<float>(z) : 0.0f;
    }
  }
  return image;
}

o3d::geometry::Image colourImage(const cv::Mat& rgb, int width, int height) {
  cv::Mat sized = rgb;
  if (rgb.empty()) {
    sized = cv::Mat(height, width, CV_8UC3, cv::Scalar(128, 128, 128));
  } else if (rgb.cols != width || rgb.rows != height) {
    cv::resize(rgb, sized, cv::Size(width, height), 0, 0, cv::INTER_AREA);
  }
  o3d::geometry::Image image;
  image.Prepare(width, height, 3, 1);
  for (int v = 0; v < height; ++v) {
    std::memcpy(image.PointerAt<std::uint8_t>(0, v, 0), sized.ptr<std::uint8_t>(v),
                static_cast<std::size_t>(width) * 3);
  }
  return image;
}

}  // namespace

TsdfMap::TsdfMap(const TsdfConfig& config)
    : config_(config),
      volume_(std::make_unique<Volume>(config.voxel_size_m, config.truncation_m,
                                       config.block_resolution)) {}

TsdfMap::~TsdfMap() = default;

void TsdfMap::clear() {
  volume_ = std::make_unique<Volume>(config_.voxel_size_m, config_.truncation_m,
                                     config_.block_resolution);
  released_pieces_.clear();
  released_bytes_ = 0;
}

void TsdfMap::integrate(const core::Frame& frame, const core::Isometry& T_W_C) {
  const core::Intrinsics& k = frame.intrinsics;
  if (!k.valid() || frame.depth_mm.type() != CV_16UC1 || frame.depth_mm.cols != k.width ||
      frame.depth_mm.rows != k.height) {
    throw core::Error(fmt::format("frame {}: depth {}x{} does not match intrinsics {}", frame.index,
                                  frame.depth_mm.cols, frame.depth_mm.rows, k.describe()));
  }
  if (thread_cap_ > 0) omp_set_num_threads(thread_cap_);

  const int step = config_.integration_scale;
  o3d::geometry::RGBDImage rgbd;
  rgbd.depth_ = depthMetres(frame.depth_mm, step, config_.min_depth_m, config_.max_depth_m);
  rgbd.color_ = colourImage(frame.rgb, rgbd.depth_.width_, rgbd.depth_.height_);
  // Pixel u of the subsampled image is pixel step*u of the original: f and c scale by 1/step.
  const o3d::camera::PinholeCameraIntrinsic intrinsic(
      rgbd.depth_.width_, rgbd.depth_.height_, k.fx / step, k.fy / step, k.cx / step, k.cy / step);
  // Open3D takes the extrinsic as world-to-camera.
  const Eigen::Matrix4d T_C_W = T_W_C.inverse().matrix();
  volume_->tsdf.Integrate(rgbd, intrinsic, T_C_W);
}

namespace {

// Appends a mesh's arrays to `into` (its vertex indices shifted past the vertices there).
void append(const std::vector<Eigen::Vector3d>& vertices,
            const std::vector<Eigen::Vector3d>& colors,
            const std::vector<Eigen::Vector3i>& triangles, SurfaceMesh& into) {
  const auto offset = static_cast<int>(into.vertices.size());
  into.vertices.insert(into.vertices.end(), vertices.begin(), vertices.end());
  into.colors.insert(into.colors.end(), colors.begin(), colors.end());
  for (const Eigen::Vector3i& t : triangles) {
    into.triangles.push_back(t + Eigen::Vector3i::Constant(offset));
  }
}

using BlockKey = std::array<int, 3>;

BlockKey keyOf(const Eigen::Vector3i& index) { return {index.x(), index.y(), index.z()}; }

// `mesh` cut into one piece per block, by the block that holds each triangle's centroid.
std::map<BlockKey, SurfaceMesh> piecesByBlock(const o3d::geometry::TriangleMesh& mesh,
                                              double block_m) {
  std::map<BlockKey, SurfaceMesh> pieces;
  std::map<BlockKey, std::unordered_map<int, int>> vertex_in_piece;
  for (const Eigen::Vector3i& t : mesh.triangles_) {
    const Eigen::Vector3d centroid =
        (mesh.vertices_[t[0]] + mesh.vertices_[t[1]] + mesh.vertices_[t[2]]) / 3.0;
    const Eigen::Vector3i block = (centroid / block_m).array().floor().cast<int>();
    const BlockKey key = keyOf(block);
    SurfaceMesh& piece = pieces[key];
    auto& local = vertex_in_piece[key];
    Eigen::Vector3i out;
    for (int corner = 0; corner < 3; ++corner) {
      const auto [it, added] = local.emplace(t[corner], static_cast<int>(piece.vertices.size()));
      if (added) {
        piece.vertices.push_back(mesh.vertices_[static_cast<std::size_t>(t[corner])]);
        piece.colors.push_back(mesh.vertex_colors_[static_cast<std::size_t>(t[corner])]);
      }
      out[corner] = it->second;
    }
    piece.triangles.push_back(out);
  }
  return pieces;
}

}  // namespace

void TsdfMap::keep(const SurfaceMesh& mesh, SurfacePiece& into) {
  // Reserved to the exact size: push_back's growth would leave up to half of each vector unused.
  const auto offset = static_cast<int>(into.vertices.size());
  into.vertices.reserve(into.vertices.size() + mesh.vertices.size());
  into.colours.reserve(into.vertices.capacity());
  into.triangles.reserve(into.triangles.size() + mesh.triangles.size());
  for (std::size_t i = 0; i < mesh.vertices.size(); ++i) {
    into.vertices.push_back(mesh.vertices[i].cast<float>());
    const Eigen::Vector3d byte =
        (mesh.colors[i].cwiseMax(0.0).cwiseMin(1.0) * 255.0).array().round();
    into.colours.push_back({static_cast<std::uint8_t>(byte.x()),
                            static_cast<std::uint8_t>(byte.y()),
                            static_cast<std::uint8_t>(byte.z())});
  }
  for (const Eigen::Vector3i& t : mesh.triangles) {
    into.triangles.push_back(t + Eigen::Vector3i::Constant(offset));
  }
}

std::size_t TsdfMap::bytesOf(const SurfacePiece& piece) {
  return piece.vertices.capacity() * (sizeof(Eigen::Vector3f) + 3) +
         piece.triangles.capacity() * sizeof(Eigen::Vector3i);
}

SurfaceMesh TsdfMap::extractMesh() const {
  SurfaceMesh out;
  // A block fused again since its release holds its surface itself.
  const auto& units = volume_->tsdf.volume_units_;
  for (const auto& [key, piece] : released_pieces_) {
    if (units.count(Eigen::Vector3i(key[0], key[1], key[2])) != 0) continue;
    const auto offset = static_cast<int>(out.vertices.size());
    for (std::size_t i = 0; i < piece.vertices.size(); ++i) {
      out.vertices.push_back(piece.vertices[i].cast<double>());
      const auto& rgb = piece.colours[i];
      out.colors.emplace_back(rgb[0] / 255.0, rgb[1] / 255.0, rgb[2] / 255.0);
    }
    for (const Eigen::Vector3i& t : piece.triangles) {
      out.triangles.push_back(t + Eigen::Vector3i::Constant(offset));
    }
  }
  const auto live = volume_->tsdf.ExtractTriangleMesh();
  append(live->vertices_, live->vertex_colors_, live->triangles_, out);
  return out;
}

std::size_t TsdfMap::releaseBlocksBehind(const core::Isometry& T_W_C, double distance_m) {
  auto& units = volume_->tsdf.volume_units_;
  const double block_m = config_.voxel_size_m * config_.block_resolution;
  const core::Isometry T_C_W = T_W_C.inverse();
  // The released blocks move into a volume of their own, whose surface is kept as a mesh (a
  // few percent of their voxels' bytes). Marching cubes needs the next block's voxels for the
  // cubes on a block's far faces, so a one-voxel seam stays open where released blocks meet
  // blocks released later or still live.
  // Made when the first block goes (most frames release none).
  std::optional<o3d::pipelines::integration::ScalableTSDFVolume> released;
  for (auto it = units.begin(); it != units.end();) {
    // Open3D keys a block by its integer index; it spans [index, index + 1) * block edge.
    const Eigen::Vector3d centre_W =
        (it->first.cast<double>() + Eigen::Vector3d::Constant(0.5)) * block_m;
    const Eigen::Vector3d centre_C = T_C_W * centre_W;
    if (centre_C.z() < 0.0 && centre_C.norm() > distance_m) {
      if (!released) {
        released.emplace(config_.voxel_size_m, config_.truncation_m,
                         o3d::pipelines::integration::TSDFVolumeColorType::RGB8,
                         config_.block_resolution);
      }
      released->volume_units_.emplace(it->first, std::move(it->second));
      it = units.erase(it);
    } else {
      ++it;
    }
  }
  if (!released) return 0;
  // A block released again replaces its piece, unless the revisit saw less than half of
  // what the piece holds (a glimpse): the fuller surface stays. A triangle whose centroid
  // strays into a neighbouring block (the seam) joins that block's piece.
  for (auto& [key, piece] : piecesByBlock(*released->ExtractTriangleMesh(), block_m)) {
    const Eigen::Vector3i index(key[0], key[1], key[2]);
    SurfacePiece& kept = released_pieces_[key];
    released_bytes_ -= bytesOf(kept);
    if (released->volume_units_.count(index) == 0) {
      keep(piece, kept);
    } else if (2 * piece.triangles.size() >= kept.triangles.size()) {
      kept = SurfacePiece{};
      keep(piece, kept);
    }
    released_bytes_ += bytesOf(kept);
  }
  return released->volume_units_.size();
}

std::size_t TsdfMap::blockCount() const { return volume_->tsdf.volume_units_.size(); }

std::size_t TsdfMap::memoryBytes() const {
  const auto r = static_cast<std::size_t>(config_.block_resolution);
  return blockCount() * r * r * r * sizeof(o3d::geometry::TSDFVoxel) + releasedSurfaceBytes();
}

void writePly(const SurfaceMesh& mesh, const std::filesystem::path& path) {
  if (mesh.vertices.empty()) {
    // Open3D refuses to write an empty mesh; a run that fused nothing still gets a valid file.
    std::ofstream out(path);
    out << "ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\n"
           "property float z\nelement face 0\nproperty list uchar int vertex_indices\n"
           "end_header\n";
    out.close();
    if (!out) {
      throw core::Error(
          fmt::format("{}: could not write the mesh (disk full or no permission?)", path.string()));
    }
    return;
  }
  o3d::geometry::TriangleMesh o3d_mesh;
  o3d_mesh.vertices_ = mesh.vertices;
  o3d_mesh.vertex_colors_ = mesh.colors;
  o3d_mesh.triangles_ = mesh.triangles;
  if (!o3d::io::WriteTriangleMesh(path.string(), o3d_mesh, /*write_ascii=*/false,
                                  /*compressed=*/false, /*write_vertex_normals=*/false)) {
    throw core::Error(
        fmt::format("{}: could not write the mesh (disk full or no permission?)", path.string()));
  }
}

}  // namespace tessera::fusion
