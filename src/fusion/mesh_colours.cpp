#include "tessera/fusion/mesh_colours.h"

#include <algorithm>
#include <cmath>
#include <utility>
#include <vector>

#include <fmt/format.h>
#include <open3d/geometry/KDTreeFlann.h>
#include <open3d/geometry/TriangleMesh.h>
#include <open3d/io/TriangleMeshIO.h>

#include "tessera/core/error.h"

namespace tessera::fusion {

// Open3D's KDTreeFlann (0.16) searches the matrix it was given in place, so the matrix lives
// beside it (found with valgrind: a local matrix left the tree reading freed memory).
struct MeshColourSampler::Tree {
  Eigen::MatrixXd points;
  open3d::geometry::KDTreeFlann index;
};

SurfaceMesh readPly(const std::filesystem::path& path) {
  if (!std::filesystem::exists(path)) {
    throw core::Error(fmt::format("{}: no such mesh", path.string()));
  }
  open3d::geometry::TriangleMesh mesh;
  if (!open3d::io::ReadTriangleMesh(path.string(), mesh) || mesh.vertices_.empty() ||
      mesh.vertex_colors_.size() != mesh.vertices_.size()) {
    throw core::Error(fmt::format("{}: not a mesh with coloured vertices", path.string()));
  }
  return {mesh.vertices_, mesh.vertex_colors_, mesh.triangles_};
}

MeshColourSampler::MeshColourSampler(const SurfaceMesh& mesh)
    : tree_(std::make_unique<Tree>()), colours_(mesh.colors) {
  Eigen::MatrixXd& points = tree_->points;
  points.resize(3, static_cast<Eigen::Index>(mesh.vertices.size()));
  for (std::size_t i = 0; i < mesh.vertices.size(); ++i) {
    points.col(static_cast<Eigen::Index>(i)) = mesh.vertices[i];
  }
  tree_->index.SetMatrixData(points);
}

MeshColourSampler::~MeshColourSampler() = default;

std::optional<Eigen::Vector3d> MeshColourSampler::colourAt(const Eigen::Vector3d& X,
                                                           double max_distance_m) const {
  std::vector<int> indices;
  std::vector<double> distance2;
  // A radius search prunes by the radius from the start; Open3D's k-nearest search would
  // wander the tree for points far from the surface.
  if (colours_.empty() || tree_->index.SearchRadius(X, max_distance_m, indices, distance2) <= 0) {
    return std::nullopt;
  }
  std::vector<std::pair<double, int>> nearest(indices.size());
  for (std::size_t j = 0; j < indices.size(); ++j) nearest[j] = {distance2[j], indices[j]};
  const std::size_t k = std::min<std::size_t>(4, nearest.size());
  std::partial_sort(nearest.begin(), nearest.begin() + static_cast<std::ptrdiff_t>(k),
                    nearest.end());
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  double total = 0.0;
  for (std::size_t j = 0; j < k; ++j) {
    const double w = 1.0 / (std::sqrt(nearest[j].first) + 1e-4);
    sum += w * colours_[static_cast<std::size_t>(nearest[j].second)];
    total += w;
  }
  return Eigen::Vector3d(255.0 * sum / total);
}

}  // namespace tessera::fusion
