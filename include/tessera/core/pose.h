#pragma once
// Rigid transforms. Names follow T_A_B: the transform mapping coordinates in frame B into
// frame A, so T_W_C maps camera coordinates into the world and T_W_C * T_C_X == T_W_X.
#include <Eigen/Geometry>

namespace tessera::core {

using Isometry = Eigen::Isometry3d;

// Builds a transform from a translation and a (not necessarily normalised) quaternion
// given as x, y, z, w, the order TUM and slambook files use.
Isometry isometryFromTranslationQuaternion(const Eigen::Vector3d& t, double qx, double qy,
                                           double qz, double qw);

// Interpolates between two poses: linear in translation, spherical in rotation.
// alpha = 0 gives a, alpha = 1 gives b.
Isometry interpolate(const Isometry& a, const Isometry& b, double alpha);

// The angle of T's rotation, degrees.
double rotationAngleDeg(const Isometry& T);

// Whether b is within radius_m and angle_deg of a (the motion between them, both bounds
// inclusive).
bool posesNear(const Isometry& a, const Isometry& b, double radius_m, double angle_deg);

}  // namespace tessera::core
