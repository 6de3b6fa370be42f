#include "tessera/core/pose.h"

#include <cmath>

namespace tessera::core {

Isometry isometryFromTranslationQuaternion(const Eigen::Vector3d& t, double qx, double qy,
                                           double qz, double qw) {
  Isometry T = Isometry::Identity();
  T.linear() = Eigen::Quaterniond(qw, qx, qy, qz).normalized().toRotationMatrix();
  T.translation() = t;
  return T;
}

Isometry interpolate(const Isometry& a, const Isometry& b, double alpha) {
  const Eigen::Quaterniond qa(a.rotation());
  const Eigen::Quaterniond qb(b.rotation());
  Isometry T = Isometry::Identity();
  T.linear() = qa.slerp(alpha, qb).toRotationMatrix();
  T.translation() = (1.0 - alpha) * a.translation() + alpha * b.translation();
  return T;
}

double rotationAngleDeg(const Isometry& T) {
  return Eigen::AngleAxisd(T.linear()).angle() * 180.0 / M_PI;
}

bool posesNear(const Isometry& a, const Isometry& b, double radius_m, double angle_deg) {
  const Isometry motion = a.inverse() * b;
  return motion.translation().norm() <= radius_m && rotationAngleDeg(motion) <= angle_deg;
}

}  // namespace tessera::core
