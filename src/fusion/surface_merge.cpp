#include "tessera/fusion/surface_merge.h"

#include <vector>

#include <open3d/geometry/KDTreeFlann.h>

namespace tessera::fusion {

SurfaceMesh mergeSurfaces(const SurfaceMesh& earlier, const SurfaceMesh& later, double overlap_m) {
  // Open3D's tree searches this matrix in place: it lives as long as the tree.
  Eigen::MatrixXd points(3, static_cast<Eigen::Index>(later.vertices.size()));
  for (std::size_t i = 0; i < later.vertices.size(); ++i) {
    points.col(static_cast<Eigen::Index>(i)) = later.vertices[i];
  }
  open3d::geometry::KDTreeFlann tree;
  if (!later.vertices.empty()) tree.SetMatrixData(points);
  std::vector<bool> covered(earlier.vertices.size(), false);
  std::vector<int> indices;
  std::vector<double> distance2;
  for (std::size_t i = 0; i < earlier.vertices.size() && !later.vertices.empty(); ++i) {
    covered[i] = tree.SearchHybrid(earlier.vertices[i], overlap_m, 1, indices, distance2) > 0;
  }
  SurfaceMesh merged = later;
  std::vector<int> index_in_merged(earlier.vertices.size(), -1);
  const auto keep = [&](int vertex) {
    auto& index = index_in_merged[static_cast<std::size_t>(vertex)];
    if (index < 0) {
      index = static_cast<int>(merged.vertices.size());
      merged.vertices.push_back(earlier.vertices[static_cast<std::size_t>(vertex)]);
      merged.colors.push_back(earlier.colors[static_cast<std::size_t>(vertex)]);
    }
    return index;
  };
  const auto inside = [&](int vertex) {
    return vertex >= 0 && static_cast<std::size_t>(vertex) < earlier.vertices.size() &&
           static_cast<std::size_t>(vertex) < earlier.colors.size();
  };
  for (const Eigen::Vector3i& triangle : earlier.triangles) {
    // A corrupt file's triangle that names no vertex is dropped, not followed.
    if (!inside(triangle[0]) || !inside(triangle[1]) || !inside(triangle[2])) continue;
    if (covered[triangle[0]] || covered[triangle[1]] || covered[triangle[2]]) continue;
    merged.triangles.emplace_back(keep(triangle[0]), keep(triangle[1]), keep(triangle[2]));
  }
  return merged;
}

}  // namespace tessera::fusion
