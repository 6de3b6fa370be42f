#pragma once
// The fused volumetric map. Open3D's ScalableTSDFVolume does the work behind this interface;
// no Open3D header leaves the fusion module.
#include <array>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <map>
#include <memory>
#include <vector>

#include <Eigen/Core>

#include "tessera/core/config.h"
#include "tessera/core/frame.h"
#include "tessera/core/pose.h"

namespace tessera::fusion {

struct TsdfConfig {
  // 2 cm: the TSDF is geometry only (textures come from the raw colour frames), and 1 cm costs
  // 3-5x the integration time and 4x the memory (measurements in docs/MEASUREMENTS.md).
  double voxel_size_m = 0.02;  // edge of one voxel
  double truncation_m = 0.06;  // TSDF truncation distance (a few voxels)
  double min_depth_m = 0.3;    // depth below this is ignored (Kinect v1 minimum ~0.4 m)
  double max_depth_m = 4.0;    // depth beyond this is ignored (noise grows with z^2)
  int block_resolution = 16;   // voxels per edge of one allocated block
  // Depth is integrated at 1/integration_scale of its resolution (every n-th pixel): the TSDF
  // is geometry only, and its cost grows with the pixels cast. Colour for texturing is taken
  // from the full-resolution frames by later stages, never from voxels.
  int integration_scale = 2;
  // Blocks behind the camera and farther than this from it are released after each frame
  // (0: keep all), so memory stays bounded on long runs; their surface is kept as a mesh. At
  // 3 m the planes there have long been finalized (patches finalize once out of view).
  double release_distance_m = 3.0;
  // Only every n-th posed frame is integrated, plus any frame taken more than 5 cm or 3 degrees
  // from the last one integrated. At 30 frames/s neighbouring frames add little to the
  // geometry; every frame is still tracked and searched for planes (patch growth and texture
  // matching depend on those: fusing planes on every 2nd frame only cost the office 2 reuses).
  int integrate_every_n_frames = 2;
  // With loop closure: keep the first integrated frame of each keyframe on disk, and fuse the
  // volume again from them at the corrected poses at the end (ReintegrationLog).
  bool correct_after_loop_closure = true;
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
  // Frees every block and released piece: the map is empty again, with its configuration.
  void clear();

  // Frees the blocks far behind the camera at T_W_C: centre farther than distance_m from it and
  // behind its image plane (so nothing the camera looks at is freed and re-allocated). Their
  // surface is kept as a mesh piece per block, which extractMesh() includes unless the block
  // was fused again on a revisit (the volume holds its surface then). A block released again
  // replaces its piece, unless it saw less than half of it: the pieces grow with the area
  // mapped, not with the laps.
  // Returns how many were freed.
  std::size_t releaseBlocksBehind(const core::Isometry& T_W_C, double distance_m);

  const TsdfConfig& config() const { return config_; }

  // Bytes held by allocated voxel blocks and the surface of released ones.
  std::size_t memoryBytes() const;
  std::size_t releasedSurfaceBytes() const { return released_bytes_; }
  std::size_t releasedPieces() const { return released_pieces_.size(); }
  std::size_t blockCount() const;

  // Caps the OpenMP threads Open3D uses inside integrate() on the calling thread.
  void setThreadCap(int threads) { thread_cap_ = threads; }

 private:
  struct Volume;
  TsdfConfig config_;
  std::unique_ptr<Volume> volume_;
  // A released block's surface as compact as the PLY it ends in: float positions, 8-bit
  // colours, vectors of exactly its size. 15 bytes a vertex and 12 a triangle, against 48 and
  // 12 (plus the growth slack of push_back) as a SurfaceMesh: a long walk's largest store.
  struct SurfacePiece {
    std::vector<Eigen::Vector3f> vertices;
    std::vector<std::array<std::uint8_t, 3>> colours;
    std::vector<Eigen::Vector3i> triangles;
  };
  // Appends `mesh` to `into`, compacted.
  static void keep(const SurfaceMesh& mesh, SurfacePiece& into);
  static std::size_t bytesOf(const SurfacePiece& piece);
  // The surface of the released blocks, by block index (Open3D's key of the block).
  std::map<std::array<int, 3>, SurfacePiece> released_pieces_;
  std::size_t released_bytes_ = 0;  // of released_pieces_, kept as they change
  int thread_cap_ = 0;            // 0: leave OpenMP's default
};

}  // namespace tessera::fusion
