#include "tessera/drivers/synthetic/scene.h"

#include <cmath>

#include <fmt/format.h>

#include "tessera/core/config.h"
#include "tessera/core/error.h"

namespace tessera::drivers::synthetic {

namespace {

Eigen::Vector3d vector3(const core::ConfigSection& s, const char* key, bool required = true) {
  std::vector<double> v;
  s.read(key, v);
  if (v.empty() && !required) return Eigen::Vector3d::Zero();
  if (v.size() != 3) {
    throw core::ConfigError(fmt::format("{}: {}.{} must be [x, y, z]", s.origin(), s.path(), key));
  }
  return {v[0], v[1], v[2]};
}

Eigen::Vector3f colour3(const core::ConfigSection& s) {
  const Eigen::Vector3d c = vector3(s, "colour", false);
  return c.cast<float>();
}

const Texture* findTexture(const Scene& scene, const core::ConfigSection& s,
                           const std::string& id) {
  const auto found = scene.textures.find(id);
  if (found == scene.textures.end()) {
    throw core::ConfigError(
        fmt::format("{}: {}: no texture with id '{}'", s.origin(), s.path(), id));
  }
  return found->second.get();
}

// Sets the plane frame from its axes: u normalised, v made orthogonal to u, n = u x v.
void setFrame(ScenePlane& plane, const Eigen::Vector3d& u, const Eigen::Vector3d& v,
              const core::ConfigSection& s) {
  if (u.norm() < 1e-9 || u.cross(v).norm() < 1e-9 * u.norm() * v.norm()) {
    throw core::ConfigError(
        fmt::format("{}: {}: u_axis and v_axis must be non-zero and not "
                    "parallel",
                    s.origin(), s.path()));
  }
  plane.u_axis = u.normalized();
  plane.v_axis = (v - plane.u_axis * plane.u_axis.dot(v)).normalized();
  plane.normal = plane.u_axis.cross(plane.v_axis);
}

void readTextureMapping(const core::ConfigSection& s, ScenePlane& plane) {
  double rotation_deg = 0.0;
  s.read("texture_rotation_deg", rotation_deg);
  plane.texture_rotation_rad = rotation_deg * M_PI / 180.0;
  s.read("texture_scale", plane.texture_scale);
  if (!(plane.texture_scale > 0.0)) {
    throw core::ConfigError(
        fmt::format("{}: {}.texture_scale must be positive", s.origin(), s.path()));
  }
  std::vector<double> offset;
  s.read("texture_offset_m", offset);
  if (!offset.empty()) {
    if (offset.size() != 2) {
      throw core::ConfigError(
          fmt::format("{}: {}.texture_offset_m must be [s, t]", s.origin(), s.path()));
    }
    plane.texture_offset_m = {offset[0], offset[1]};
  }
}

ScenePlane readPlane(const Scene& scene, const core::ConfigSection& s) {
  ScenePlane plane;
  s.read("id", plane.id);
  s.read("texture", plane.texture_id);
  plane.texture = findTexture(scene, s, plane.texture_id);
  plane.origin = vector3(s, "origin");
  setFrame(plane, vector3(s, "u_axis"), vector3(s, "v_axis"), s);
  std::vector<std::vector<double>> polygon;
  s.read("polygon", polygon);
  for (const auto& p : polygon) {
    if (p.size() != 2) {
      throw core::ConfigError(
          fmt::format("{}: {}.polygon points must be [u, v]", s.origin(), s.path()));
    }
    plane.polygon.emplace_back(p[0], p[1]);
  }
  if (plane.polygon.size() < 3) {
    throw core::ConfigError(
        fmt::format("{}: {}.polygon needs at least 3 points", s.origin(), s.path()));
  }
  readTextureMapping(s, plane);
  return plane;
}

// An axis-aligned box as planar faces with outward normals (no bottom face).
std::vector<ScenePlane> readBox(const Scene& scene, const core::ConfigSection& s) {
  std::string id, top_texture, side_texture;
  s.read("id", id);
  s.read("top_texture", top_texture);
  side_texture = top_texture;
  s.read("side_texture", side_texture);
  const Eigen::Vector3d lo = vector3(s, "min"), hi = vector3(s, "max");
  if ((hi - lo).minCoeff() <= 0.0) {
    throw core::ConfigError(
        fmt::format("{}: {}: max must exceed min on every axis", s.origin(), s.path()));
  }
  const Eigen::Vector3d size = hi - lo;
  struct Face {
    const char* name;
    Eigen::Vector3d origin, u, v;
    double width, height;
    bool top;
  };
  const Eigen::Vector3d x = Eigen::Vector3d::UnitX(), y = Eigen::Vector3d::UnitY(),
                        z = Eigen::Vector3d::UnitZ();
  const Face faces[] = {
      {"top", {lo.x(), lo.y(), hi.z()}, x, y, size.x(), size.y(), true},
      {"front", {lo.x(), lo.y(), lo.z()}, x, z, size.x(), size.z(), false},
      {"back", {hi.x(), hi.y(), lo.z()}, -x, z, size.x(), size.z(), false},
      {"left", {lo.x(), hi.y(), lo.z()}, -y, z, size.y(), size.z(), false},
      {"right", {hi.x(), lo.y(), lo.z()}, y, z, size.y(), size.z(), false},
  };
  std::vector<ScenePlane> planes;
  for (const Face& face : faces) {
    ScenePlane plane;
    plane.id = fmt::format("{}.{}", id, face.name);
    plane.texture_id = face.top ? top_texture : side_texture;
    plane.texture = findTexture(scene, s, plane.texture_id);
    plane.origin = face.origin;
    setFrame(plane, face.u, face.v, s);
    plane.polygon = {{0, 0}, {face.width, 0}, {face.width, face.height}, {0, face.height}};
    if (face.top) readTextureMapping(s, plane);
    planes.push_back(std::move(plane));
  }
  return planes;
}

Eigen::Vector3d catmullRom(const Eigen::Vector3d& p0, const Eigen::Vector3d& p1,
                           const Eigen::Vector3d& p2, const Eigen::Vector3d& p3, double t) {
  const double t2 = t * t, t3 = t2 * t;
  return 0.5 * ((2 * p1) + (-p0 + p2) * t + (2 * p0 - 5 * p1 + 4 * p2 - p3) * t2 +
                (-p0 + 3 * p1 - 3 * p2 + p3) * t3);
}

}  // namespace

Eigen::Vector2d ScenePlane::textureCoordinates(const Eigen::Vector2d& uv) const {
  const Eigen::Rotation2Dd rotation(texture_rotation_rad);
  return rotation * uv / texture_scale + texture_offset_m;
}

double ScenePlane::area() const {
  double twice = 0.0;  // shoelace formula
  for (std::size_t i = 0; i < polygon.size(); ++i) {
    const auto& a = polygon[i];
    const auto& b = polygon[(i + 1) % polygon.size()];
    twice += a.x() * b.y() - b.x() * a.y();
  }
  return std::abs(twice) / 2;
}

core::Isometry Scene::cameraPose(int frame) const {
  const int n = static_cast<int>(waypoints.size());
  const double param = frames > 1 ? static_cast<double>(frame) / (frames - 1) * (n - 1) : 0.0;
  const int k = std::min(static_cast<int>(std::floor(param)), std::max(n - 2, 0));
  const double t = param - k;
  const auto at = [&](int i) {
    return waypoints[static_cast<std::size_t>(std::clamp(i, 0, n - 1))];
  };
  Eigen::Vector3d position = at(k).position, look = at(k).look_at;
  if (n > 1) {
    position =
        catmullRom(at(k - 1).position, at(k).position, at(k + 1).position, at(k + 2).position, t);
    look = catmullRom(at(k - 1).look_at, at(k).look_at, at(k + 1).look_at, at(k + 2).look_at, t);
  }
  // Camera axes: z forward, x right, y down, with world +z up.
  const Eigen::Vector3d forward = (look - position).normalized();
  Eigen::Vector3d right = forward.cross(Eigen::Vector3d::UnitZ());
  if (right.norm() < 1e-6) right = Eigen::Vector3d::UnitX();  // looking straight up or down
  right.normalize();
  const Eigen::Vector3d down = forward.cross(right);
  core::Isometry T_W_C = core::Isometry::Identity();
  T_W_C.linear().col(0) = right;
  T_W_C.linear().col(1) = down;
  T_W_C.linear().col(2) = forward;
  T_W_C.translation() = position;
  return T_W_C;
}

std::int64_t Scene::timestampNs(int frame) const {
  // Start at 1 s (OpenNI2 ignores a frame stamped 0), in whole microseconds (ONI's unit).
  return 1'000'000'000LL + 1000LL * static_cast<std::int64_t>(std::llround(frame * 1e6 / fps));
}

Scene loadScene(const std::filesystem::path& path) {
  const core::ConfigDocument doc = core::ConfigDocument::load(path);
  const core::ConfigSection root = doc.root();
  Scene scene;
  scene.directory = std::filesystem::absolute(path).parent_path();
  root.read("name", scene.name);
  int seed = 1;
  root.read("seed", seed);
  scene.seed = static_cast<std::uint32_t>(seed);
  root.read("frames", scene.frames);
  root.read("fps", scene.fps);
  std::string sensor = "kinect_v1";
  root.read("sensor", sensor);
  try {
    scene.sensor = SensorProfile::named(sensor);
  } catch (const core::ConfigError& e) {
    throw core::ConfigError(fmt::format("{}: sensor: {}", path.string(), e.what()));
  }
  root.read("colour_registered", scene.sensor.colour_registered);
  if (scene.frames < 1 || !(scene.fps > 0.0)) {
    throw core::ConfigError(fmt::format("{}: frames and fps must be positive", path.string()));
  }
  const std::string dir = path.parent_path().string();
  for (const auto& entry : root.list("textures")) {
    std::string id;
    entry.read("id", id);
    if (id.empty() || scene.textures.contains(id)) {
      throw core::ConfigError(fmt::format("{}: {}: texture ids must be unique and non-empty",
                                          path.string(), entry.path()));
    }
    scene.textures[id] = makeTexture(entry, dir);
    scene.texture_definitions[id] = entry.toYaml();
  }
  for (const auto& entry : root.list("planes")) scene.planes.push_back(readPlane(scene, entry));
  for (const auto& entry : root.list("boxes")) {
    for (auto& plane : readBox(scene, entry)) scene.planes.push_back(std::move(plane));
  }
  for (const auto& entry : root.list("spheres")) {
    SceneSphere sphere{vector3(entry, "centre"), 0.1, colour3(entry)};
    entry.read("radius", sphere.radius);
    scene.spheres.push_back(sphere);
  }
  for (const auto& entry : root.list("cylinders")) {
    SceneCylinder cylinder{vector3(entry, "base"), 0.03, 0.7, colour3(entry)};
    entry.read("radius", cylinder.radius);
    entry.read("height", cylinder.height);
    scene.cylinders.push_back(cylinder);
  }
  for (const auto& entry : root.section("camera").list("waypoints")) {
    scene.waypoints.push_back({vector3(entry, "position"), vector3(entry, "look_at")});
  }
  if (scene.waypoints.empty()) {
    throw core::ConfigError(
        fmt::format("{}: camera.waypoints lists no camera position", path.string()));
  }
  doc.checkAllKeysUsed();
  return scene;
}

}  // namespace tessera::drivers::synthetic
