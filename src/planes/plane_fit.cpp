#include "tessera/planes/plane_fit.h"

#include <algorithm>
#include <cmath>

#include <Eigen/Eigenvalues>

namespace tessera::planes {

PlaneFit fitPlane(const PointMoments& moments) {
  PlaneFit plane;
  plane.centroid = moments.sum / moments.count;
  const Eigen::Matrix3d scatter =
      moments.outer / moments.count - plane.centroid * plane.centroid.transpose();
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver(scatter);  // eigenvalues ascend
  plane.normal = solver.eigenvectors().col(0);
  plane.major_axis = solver.eigenvectors().col(2);
  plane.offset = plane.normal.dot(plane.centroid);
  plane.rms_residual_m = std::sqrt(std::max(0.0, solver.eigenvalues()(0)));
  return plane;
}

}  // namespace tessera::planes
