#pragma once
// The global set of planar patches: detected regions are associated with the patches they
// continue (same plane within bounds, and touching what the patch already covers), patches
// found to be one plane are merged, and each patch's plane is refitted from all its points.
#include <cstddef>
#include <set>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "tessera/core/frame.h"
#include "tessera/core/pose.h"
#include "tessera/planes/plane_detector.h"
#include "tessera/planes/plane_fit.h"

namespace tessera::planes {

struct PatchMapConfig {
  double max_normal_angle_deg = 5.0;  // a region continues a patch only this close in normal
  double max_offset_m = 0.03;         // ... and with its centroid this close to the plane
  double cell_m = 0.05;               // occupancy grid cell in the plane
};

// One detected region in world coordinates.
struct PlaneObservation {
  std::vector<Eigen::Vector3d> points_W;
};

// The regions of `detection` as world points (frame seen from T_W_C).
std::vector<PlaneObservation> observationsOf(const core::Frame& frame,
                                             const PlaneDetection& detection,
                                             const core::Isometry& T_W_C);

using Cell = std::pair<int, int>;

struct Patch {
  int id = 0;
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();  // n . X = offset
  double offset = 0.0;
  // In-plane frame fixed when the patch is created: cells are indexed in (u, v) from origin.
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();
  Eigen::Vector3d u_axis = Eigen::Vector3d::UnitX();
  Eigen::Vector3d v_axis = Eigen::Vector3d::UnitY();
  std::set<Cell> cells;
  PointMoments moments;  // of every point ever added, for the least-squares refit

  Cell cellOf(const Eigen::Vector3d& X_W, double cell_m) const;
  Eigen::Vector3d cellCentre(const Cell& cell, double cell_m) const;
};

class PatchMap {
 public:
  explicit PatchMap(const PatchMapConfig& config) : config_(config) {}

  // Adds one frame's regions; returns, per region, the id of the patch it went to.
  std::vector<int> add(const std::vector<PlaneObservation>& observations);

  const std::vector<Patch>& patches() const { return patches_; }
  // Area covered by a patch's occupied cells, m^2.
  double areaM2(const Patch& patch) const;

 private:
  bool continues(const Patch& patch, const Eigen::Vector3d& normal, double offset,
                 const std::vector<Eigen::Vector3d>& points) const;
  void absorb(Patch& into, const Patch& other) const;
  void addObservation(Patch& patch, const std::vector<Eigen::Vector3d>& points,
                      const PointMoments& moments) const;
  static void refit(Patch& patch);

  PatchMapConfig config_;
  std::vector<Patch> patches_;
  int next_id_ = 0;
};

}  // namespace tessera::planes
