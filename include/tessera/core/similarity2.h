#pragma once
// A 2D similarity transform p' = s R(theta) p + t, kept as a = s cos(theta), b = s sin(theta):
// rotation, uniform scale and translation. Texture instances map a patch's texel coordinates
// (column, row) into the texel coordinates of the texture they reuse with one of these.
#include <cmath>

#include <Eigen/Core>

namespace tessera::core {

struct Similarity2 {
  double a = 1.0, b = 0.0;    // s cos(theta), s sin(theta)
  double tx = 0.0, ty = 0.0;  // translation

  static Similarity2 fromAngleScale(double angle_rad, double scale, double tx, double ty) {
    return {scale * std::cos(angle_rad), scale * std::sin(angle_rad), tx, ty};
  }
  Eigen::Vector2d apply(const Eigen::Vector2d& p) const {
    return {a * p.x() - b * p.y() + tx, b * p.x() + a * p.y() + ty};
  }
  double scale() const { return std::hypot(a, b); }
  double angleRad() const { return std::atan2(b, a); }
  // q = inverse().apply(apply(q)).
  Similarity2 inverse() const {
    const double s2 = a * a + b * b;
    const double ia = a / s2, ib = -b / s2;
    return {ia, ib, -(ia * tx - ib * ty), -(ib * tx + ia * ty)};
  }
  // First this, then `after`.
  Similarity2 then(const Similarity2& after) const {
    return {after.a * a - after.b * b, after.b * a + after.a * b,
            after.a * tx - after.b * ty + after.tx, after.b * tx + after.a * ty + after.ty};
  }
};

}  // namespace tessera::core
