#pragma once
// Geometry shared by the ground-truth evaluations: vectors and polygons from the JSON of
// .gt.json and patches.json, and planes with an in-plane frame.
#include <vector>

#include <Eigen/Core>
#include <nlohmann/json.hpp>

namespace tessera::eval {

using Polygon = std::vector<Eigen::Vector2d>;

inline Eigen::Vector3d vec3(const nlohmann::json& j) {
  return {j.at(0).get<double>(), j.at(1).get<double>(), j.at(2).get<double>()};
}

inline Polygon polygonOf(const nlohmann::json& j) {
  Polygon polygon;
  for (const auto& p : j) polygon.emplace_back(p.at(0).get<double>(), p.at(1).get<double>());
  return polygon;
}

// Crossing-number test.
inline bool inside(const Eigen::Vector2d& p, const Polygon& polygon) {
  bool in = false;
  for (std::size_t i = 0, j = polygon.size() - 1; i < polygon.size(); j = i++) {
    const Eigen::Vector2d& a = polygon[i];
    const Eigen::Vector2d& b = polygon[j];
    if ((a.y() > p.y()) != (b.y() > p.y()) &&
        p.x() < (b.x() - a.x()) * (p.y() - a.y()) / (b.y() - a.y()) + a.x()) {
      in = !in;
    }
  }
  return in;
}

// A plane with an in-plane frame: n . X = d, X = origin + u * u_axis + v * v_axis.
struct FramedPlane {
  Eigen::Vector3d normal, origin, u_axis, v_axis;
  double offset = 0.0;
  Eigen::Vector2d uvOf(const Eigen::Vector3d& X) const {
    return {(X - origin).dot(u_axis), (X - origin).dot(v_axis)};
  }
  Eigen::Vector3d pointAt(const Eigen::Vector2d& uv) const {
    return origin + uv.x() * u_axis + uv.y() * v_axis;
  }
};

}  // namespace tessera::eval
