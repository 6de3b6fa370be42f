#pragma once
// A synthetic scene: textured planar polygons, some non-planar clutter and a camera path,
// described in YAML (config/scenes/*.yaml; keys documented in docs/SCENES.md).
#include <filesystem>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "tessera/core/pose.h"
#include "tessera/drivers/synthetic/sensor_model.h"
#include "tessera/drivers/synthetic/texture.h"

namespace tessera::drivers::synthetic {

// A planar polygon. Plane coordinates (u, v) are metres along `u_axis`, `v_axis` from `origin`;
// texture coordinates are (s, t) = R(texture_rotation) * (u, v) / texture_scale + offset.
struct ScenePlane {
  std::string id;
  std::string texture_id;
  const Texture* texture = nullptr;
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();
  Eigen::Vector3d u_axis = Eigen::Vector3d::UnitX();
  Eigen::Vector3d v_axis = Eigen::Vector3d::UnitY();
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();  // u x v
  std::vector<Eigen::Vector2d> polygon;               // outline in (u, v), metres
  double texture_rotation_rad = 0.0;
  double texture_scale = 1.0;
  Eigen::Vector2d texture_offset_m = Eigen::Vector2d::Zero();

  Eigen::Vector2d textureCoordinates(const Eigen::Vector2d& uv) const;
  // Plane offset d in n . X = d.
  double offset() const { return normal.dot(origin); }
  double area() const;
};

// Non-planar clutter: spheres and vertical cylinders of one colour.
struct SceneSphere {
  Eigen::Vector3d centre;
  double radius = 0.1;
  Eigen::Vector3f colour;
};
struct SceneCylinder {
  Eigen::Vector3d base;  // centre of the bottom disc; the axis is world +z
  double radius = 0.03;
  double height = 0.7;
  Eigen::Vector3f colour;
};

struct CameraWaypoint {
  Eigen::Vector3d position;
  Eigen::Vector3d look_at;
};

struct Scene {
  std::string name;
  std::uint32_t seed = 1;
  int frames = 300;
  double fps = 30.0;
  SensorProfile sensor;
  std::map<std::string, std::unique_ptr<Texture>> textures;
  std::map<std::string, std::string> texture_definitions;  // each texture's scene entry, YAML
  std::filesystem::path directory;  // the scene file's folder (absolute): image paths start here
  std::vector<ScenePlane> planes;
  std::vector<SceneSphere> spheres;
  std::vector<SceneCylinder> cylinders;
  std::vector<CameraWaypoint> waypoints;

  // Camera pose of frame i: a smooth (Catmull-Rom) path through the waypoints, camera looking
  // at the interpolated look-at point with world +z up.
  core::Isometry cameraPose(int frame) const;
  std::int64_t timestampNs(int frame) const;
};

// Loads a scene file; throws core::ConfigError naming the file and the key on any problem.
Scene loadScene(const std::filesystem::path& path);

}  // namespace tessera::drivers::synthetic
