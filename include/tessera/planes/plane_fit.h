#pragma once
// Least-squares plane fitting from accumulated point moments, shared by per-frame detection
// and the patch map (which keeps adding points to a patch over many frames).
#include <Eigen/Core>

namespace tessera::planes {

// Count, sum and sum of outer products of points: enough to refit a plane at any time.
struct PointMoments {
  double count = 0.0;
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  Eigen::Matrix3d outer = Eigen::Matrix3d::Zero();

  void add(const Eigen::Vector3d& X) {
    count += 1.0;
    sum += X;
    outer += X * X.transpose();
  }
  void add(const PointMoments& other) {
    count += other.count;
    sum += other.sum;
    outer += other.outer;
  }
};

struct PlaneFit {
  Eigen::Vector3d normal;  // unit; its sign is arbitrary
  double offset = 0.0;     // n . X = offset
  Eigen::Vector3d centroid;
  Eigen::Vector3d major_axis;  // in-plane direction of largest spread
  double rms_residual_m = 0.0;
};

// The plane through the centroid whose normal is the scatter matrix's smallest eigenvector.
// Needs moments of at least 3 points.
PlaneFit fitPlane(const PointMoments& moments);

}  // namespace tessera::planes
