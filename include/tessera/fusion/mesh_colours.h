#pragma once
// Colours of the TSDF's surface mesh at arbitrary points: what texturing from voxel colours
// gives, the baseline tessera's bitmaps are measured against.
#include <filesystem>
#include <memory>
#include <optional>

#include <Eigen/Core>

#include "tessera/fusion/tsdf_map.h"

namespace tessera::fusion {

// Reads a PLY mesh with vertex colours (as writePly writes it); throws core::Error naming the
// file when it is missing, unreadable or has no coloured vertices.
SurfaceMesh readPly(const std::filesystem::path& path);

class MeshColourSampler {
 public:
  explicit MeshColourSampler(const SurfaceMesh& mesh);
  ~MeshColourSampler();
  MeshColourSampler(const MeshColourSampler&) = delete;
  MeshColourSampler& operator=(const MeshColourSampler&) = delete;

  // RGB in [0, 255] at X: the inverse-distance weighted mean of the 4 nearest vertex colours
  // within max_distance_m (marching cubes vertex colours interpolate the voxel colours), or
  // nothing when no vertex is that close. Thread-safe.
  std::optional<Eigen::Vector3d> colourAt(const Eigen::Vector3d& X, double max_distance_m) const;

 private:
  struct Tree;
  std::unique_ptr<Tree> tree_;
  std::vector<Eigen::Vector3d> colours_;
};

}  // namespace tessera::fusion
