#pragma once
// The fused volumetric map. Open3D's ScalableTSDFVolume does the work behind this interface;
// no Open3D header leaves the fusion module.
#include <cstddef>
#include <filesystem>
#include <memory>
#include <vector>

#include <Eigen/Core>

#include "tessera/core/config.h"
#include "tessera/core/frame.h"
#include "tessera/core/pose.h"

namespace tessera::fusion {

struct TsdfConfig {
  double voxel_size_m = 0.01;  // edge of one voxel
  double truncation_m = 0.04;  // TSDF truncation distance (a few voxels)
  double min_depth_m = 0.3;    // depth below this is ignored (Kinect v1 minimum ~0.4 m)
  double max_depth_m = 4.0;    // depth beyond this is ignored (noise grows with z^2)
  int block_resolution = 16;   // voxels per edge of one allocated block
};

// Reads the `tsdf:` keys of a config section into `config`.
void readConfig(const core::ConfigSection& section, TsdfConfig& config);

// A triangle mesh with per-vertex colour (RGB in [0, 1]) in world coordinates.
struct SurfaceMesh {
  std::vector<Eigen::Vector3d> vertices;
  std::vector<Eigen::Vector3d> colors;
  std::vector<Eigen::Vector3i> triangles;
};

// Writes a binary PLY; throws core::Error naming the file when it cannot be written.
void writePly(const SurfaceMesh& mesh, const std::filesystem::path& path);

// Not thread-safe: owned by the fusion stage, which the flow graph runs serially.
class TsdfMap {
 public:
  explicit TsdfMap(const TsdfConfig& config);
  ~TsdfMap();
  TsdfMap(const TsdfMap&) = delete;
  TsdfMap& operator=(const TsdfMap&) = delete;

  // Fuses `frame` seen from camera pose T_W_C. Colour is resampled to the depth size
  // when they differ. Throws core::Error if the frame has no valid intrinsics.
  void integrate(const core::Frame& frame, const core::Isometry& T_W_C);

  // Zero-crossing surface by marching cubes.
  SurfaceMesh extractMesh() const;

  // Bytes held by allocated voxel blocks.
  std::size_t memoryBytes() const;
  std::size_t blockCount() const;

  // Caps the OpenMP threads Open3D uses inside integrate() on the calling thread.
  void setThreadCap(int threads) { thread_cap_ = threads; }

 private:
  struct Volume;
  TsdfConfig config_;
  std::unique_ptr<Volume> volume_;
  int thread_cap_ = 0;  // 0: leave OpenMP's default
};

}  // namespace tessera::fusion
