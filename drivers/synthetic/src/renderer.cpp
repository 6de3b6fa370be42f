#include "tessera/drivers/synthetic/renderer.h"

#include <cmath>
#include <limits>

#include <opencv2/core/utility.hpp>

namespace tessera::drivers::synthetic {

namespace {

struct Hit {
  double z = std::numeric_limits<double>::infinity();  // depth along the camera's z axis
  double cos_incidence = 0.0;
  int surface = -2;  // plane index, -1 clutter, -2 nothing
  cv::Vec3f colour{0, 0, 0};
};

bool insidePolygon(const std::vector<Eigen::Vector2d>& polygon, const Eigen::Vector2d& p) {
  bool inside = false;  // even-odd rule
  for (std::size_t i = 0, j = polygon.size() - 1; i < polygon.size(); j = i++) {
    const auto& a = polygon[i];
    const auto& b = polygon[j];
    if ((a.y() > p.y()) != (b.y() > p.y()) &&
        p.x() < (b.x() - a.x()) * (p.y() - a.y()) / (b.y() - a.y()) + a.x()) {
      inside = !inside;
    }
  }
  return inside;
}

struct PlaneCache {
  Eigen::Vector2d lo, hi;  // bounding box of the polygon in (u, v)
};

// The nearest surface along the ray origin + z * ray (ray has unit camera-z component, so the
// ray parameter is the depth z).
Hit castRay(const Scene& scene, const std::vector<PlaneCache>& cache, const Eigen::Vector3d& origin,
            const Eigen::Vector3d& ray) {
  Hit hit;
  for (std::size_t i = 0; i < scene.planes.size(); ++i) {
    const ScenePlane& plane = scene.planes[i];
    const double denominator = plane.normal.dot(ray);
    if (std::abs(denominator) < 1e-12) continue;
    const double z = (plane.offset() - plane.normal.dot(origin)) / denominator;
    if (z <= 1e-6 || z >= hit.z) continue;
    const Eigen::Vector3d X = origin + z * ray - plane.origin;
    const Eigen::Vector2d uv(X.dot(plane.u_axis), X.dot(plane.v_axis));
    if ((uv.array() < cache[i].lo.array()).any() || (uv.array() > cache[i].hi.array()).any())
      continue;
    if (!insidePolygon(plane.polygon, uv)) continue;
    hit.z = z;
    hit.cos_incidence = std::abs(denominator) / ray.norm();
    hit.surface = static_cast<int>(i);
    const Eigen::Vector2d st = plane.textureCoordinates(uv);
    hit.colour = plane.texture->colour(st.x(), st.y());
  }
  for (const SceneSphere& sphere : scene.spheres) {
    // |o + z r - c|^2 = R^2
    const Eigen::Vector3d oc = origin - sphere.centre;
    const double a = ray.squaredNorm(), b = 2 * oc.dot(ray),
                 c = oc.squaredNorm() - sphere.radius * sphere.radius;
    const double disc = b * b - 4 * a * c;
    if (disc < 0) continue;
    const double z = (-b - std::sqrt(disc)) / (2 * a);
    if (z <= 1e-6 || z >= hit.z) continue;
    const Eigen::Vector3d normal = (oc + z * ray).normalized();
    hit.z = z;
    hit.cos_incidence = std::abs(normal.dot(ray)) / ray.norm();
    hit.surface = -1;
    hit.colour = cv::Vec3f(sphere.colour.x(), sphere.colour.y(), sphere.colour.z());
  }
  for (const SceneCylinder& cylinder : scene.cylinders) {
    // Vertical cylinder: solve in x-y, then clip to its height.
    const Eigen::Vector2d oc = (origin - cylinder.base).head<2>(), r = ray.head<2>();
    const double a = r.squaredNorm(), b = 2 * oc.dot(r),
                 c = oc.squaredNorm() - cylinder.radius * cylinder.radius;
    const double disc = b * b - 4 * a * c;
    if (a < 1e-12 || disc < 0) continue;
    const double z = (-b - std::sqrt(disc)) / (2 * a);
    const double height = origin.z() + z * ray.z() - cylinder.base.z();
    if (z <= 1e-6 || z >= hit.z || height < 0 || height > cylinder.height) continue;
    Eigen::Vector3d normal;
    normal << (oc + z * r).normalized(), 0.0;
    hit.z = z;
    hit.cos_incidence = std::abs(normal.dot(ray)) / ray.norm();
    hit.surface = -1;
    hit.colour = cv::Vec3f(cylinder.colour.x(), cylinder.colour.y(), cylinder.colour.z());
  }
  return hit;
}

}  // namespace

CleanView renderClean(const Scene& scene, const core::Intrinsics& k, const core::Isometry& T_W_C,
                      int supersample) {
  std::vector<PlaneCache> cache;
  for (const ScenePlane& plane : scene.planes) {
    PlaneCache c{plane.polygon.front(), plane.polygon.front()};
    for (const auto& p : plane.polygon) c.lo = c.lo.cwiseMin(p), c.hi = c.hi.cwiseMax(p);
    cache.push_back(c);
  }
  CleanView view;
  view.depth_m.create(k.height, k.width, CV_64FC1);
  view.colour.create(k.height, k.width, CV_32FC3);
  view.cos_incidence.create(k.height, k.width, CV_64FC1);
  view.surface_id.create(k.height, k.width, CV_32SC1);
  const Eigen::Matrix3d R = T_W_C.linear();
  const Eigen::Vector3d origin = T_W_C.translation();
  const int s = std::max(supersample, 1);

  cv::parallel_for_(cv::Range(0, k.height), [&](const cv::Range& rows) {
    for (int v = rows.start; v < rows.end; ++v) {
      for (int u = 0; u < k.width; ++u) {
        const auto rayAt = [&](double pu, double pv) {
          return Eigen::Vector3d(R * Eigen::Vector3d((pu - k.cx) / k.fx, (pv - k.cy) / k.fy, 1.0));
        };
        const Hit centre = castRay(scene, cache, origin, rayAt(u, v));
        const bool found = centre.surface != -2;
        view.depth_m.at<double>(v, u) = found ? centre.z : 0.0;
        view.cos_incidence.at<double>(v, u) = centre.cos_incidence;
        view.surface_id.at<int>(v, u) = centre.surface;
        cv::Vec3f colour(0, 0, 0);
        for (int i = 0; i < s; ++i) {
          for (int j = 0; j < s; ++j) {
            const double pu = u - 0.5 + (i + 0.5) / s, pv = v - 0.5 + (j + 0.5) / s;
            colour += castRay(scene, cache, origin, rayAt(pu, pv)).colour;
          }
        }
        view.colour.at<cv::Vec3f>(v, u) = colour / static_cast<float>(s * s);
      }
    }
  });
  return view;
}

SyntheticSource::SyntheticSource(const std::filesystem::path& scene_file)
    : name_(scene_file.string()), scene_(loadScene(scene_file)) {}

core::ReadResult SyntheticSource::read() {
  core::ReadResult result;
  if (next_ >= scene_.frames) return result;
  const int i = next_++;
  core::Frame& frame = result.frame;
  frame.index = static_cast<std::uint64_t>(i);
  frame.timestamp_ns = scene_.timestampNs(i);
  frame.intrinsics = scene_.sensor.intrinsics;
  frame.T_W_C_gt = scene_.cameraPose(i);
  CleanView view = renderClean(scene_, frame.intrinsics, *frame.T_W_C_gt);
  if (!scene_.sensor.colour_registered) {
    // Colour from its own camera beside the depth camera, with the same lens.
    core::Isometry T_D_RGB = core::Isometry::Identity();
    T_D_RGB.translation().x() = scene_.sensor.colour_baseline_m;
    view.colour = renderClean(scene_, frame.intrinsics, *frame.T_W_C_gt * T_D_RGB).colour;
    frame.colour_camera = core::ColourCamera{frame.intrinsics, T_D_RGB.inverse()};
  }
  applySensor(
      scene_.sensor, view,
      static_cast<std::uint64_t>(scene_.seed) * 1'000'003ULL + static_cast<std::uint64_t>(i),
      frame.depth_mm, frame.rgb);
  result.status = core::ReadStatus::kFrame;
  return result;
}

}  // namespace tessera::drivers::synthetic
