#include "tessera/eval/plane_evaluation.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>

#include <fmt/format.h>
#include <opencv2/imgproc.hpp>

#include "internal/truth_geometry.h"
#include "tessera/core/error.h"

namespace tessera::eval {

namespace {

struct TruthPlane {
  std::string id;
  FramedPlane plane;
  Polygon polygon;
  double area_m2 = 0.0;
  int parent = -1;  // the plane this one lies on (an overlay), or -1
  // Raster over the polygon's bounding box plus a margin, cell_m per cell.
  Eigen::Vector2d grid_min;
  cv::Mat seen, in_polygon;
};

struct PatchOutline {
  Polygon outer;
  std::vector<Polygon> holes;
};

struct RunPatch {
  int id = 0;
  FramedPlane plane;  // in the run's world frame
  std::vector<PatchOutline> parts;
  // Of its outline, and its normal, in the truth's world frame.
  Eigen::Vector3d centroid_W = Eigen::Vector3d::Zero();
  Eigen::Vector3d normal_W = Eigen::Vector3d::UnitZ();
};

bool covers(const RunPatch& patch, const Eigen::Vector2d& uv) {
  for (const PatchOutline& part : patch.parts) {
    if (!inside(uv, part.outer)) continue;
    bool in_hole = false;
    for (const Polygon& hole : part.holes) in_hole = in_hole || inside(uv, hole);
    if (!in_hole) return true;
  }
  return false;
}

// Area-weighted centroid of a polygon (shoelace), and its area.
std::pair<Eigen::Vector2d, double> centroidOf(const Polygon& polygon) {
  double twice_area = 0.0;
  Eigen::Vector2d sum = Eigen::Vector2d::Zero();
  for (std::size_t i = 0; i < polygon.size(); ++i) {
    const Eigen::Vector2d& a = polygon[i];
    const Eigen::Vector2d& b = polygon[(i + 1) % polygon.size()];
    const double cross = a.x() * b.y() - b.x() * a.y();
    twice_area += cross;
    sum += (a + b) * cross;
  }
  if (std::abs(twice_area) < 1e-12) return {polygon.empty() ? sum : polygon.front(), 0.0};
  return {sum / (3.0 * twice_area), std::abs(twice_area) / 2.0};
}

std::vector<TruthPlane> readTruthPlanes(const nlohmann::json& truth, double cell_m) {
  if (!truth.contains("planes")) throw core::Error("ground truth has no \"planes\"");
  std::vector<TruthPlane> planes;
  constexpr double kMargin = 0.5;
  for (const auto& p : truth.at("planes")) {
    TruthPlane plane;
    plane.id = p.at("id").get<std::string>();
    plane.plane = {vec3(p.at("normal")), vec3(p.at("origin")), vec3(p.at("u_axis")),
                   vec3(p.at("v_axis")), p.at("offset_m").get<double>()};
    plane.polygon = polygonOf(p.at("polygon_uv"));
    plane.area_m2 = centroidOf(plane.polygon).second;
    Eigen::Vector2d lo = plane.polygon.front(), hi = lo;
    for (const auto& q : plane.polygon) lo = lo.cwiseMin(q), hi = hi.cwiseMax(q);
    plane.grid_min = lo - Eigen::Vector2d::Constant(kMargin);
    const Eigen::Vector2d size = (hi - lo + Eigen::Vector2d::Constant(2 * kMargin)) / cell_m;
    plane.seen = cv::Mat::zeros(static_cast<int>(std::ceil(size.y())),
                                static_cast<int>(std::ceil(size.x())), CV_8UC1);
    plane.in_polygon = plane.seen.clone();
    for (int r = 0; r < plane.seen.rows; ++r) {
      for (int c = 0; c < plane.seen.cols; ++c) {
        const Eigen::Vector2d uv = plane.grid_min + cell_m * Eigen::Vector2d(c + 0.5, r + 0.5);
        if (inside(uv, plane.polygon)) plane.in_polygon.at<std::uint8_t>(r, c) = 255;
      }
    }
    planes.push_back(std::move(plane));
  }
  return planes;
}

// A plane lying on a larger one (same side, within the offset bound, its corners inside the
// other's polygon) is a texture on it, not geometry a depth camera can tell apart.
void findOverlays(std::vector<TruthPlane>& planes, const PlaneEvaluationOptions& options) {
  const double cos_bound = std::cos(options.max_normal_deg * M_PI / 180.0);
  for (TruthPlane& small : planes) {
    for (std::size_t j = 0; j < planes.size(); ++j) {
      const TruthPlane& big = planes[j];
      if (&big == &small || big.area_m2 <= small.area_m2) continue;
      if (small.plane.normal.dot(big.plane.normal) < cos_bound) continue;
      if (std::abs(small.plane.offset - big.plane.offset) > options.max_offset_m) continue;
      const bool corners_inside =
          std::all_of(small.polygon.begin(), small.polygon.end(), [&](const Eigen::Vector2d& uv) {
            return inside(big.plane.uvOf(small.plane.pointAt(uv)), big.polygon);
          });
      if (corners_inside) small.parent = static_cast<int>(j);
    }
  }
}

// Marks, in each plane's raster, the cells the camera saw it at (nearest surface along each
// ray, within the depth range), from the ground-truth poses.
void markSeen(std::vector<TruthPlane>& planes, const nlohmann::json& truth,
              const core::Trajectory& poses, const PlaneEvaluationOptions& options) {
  const auto& k = truth.at("intrinsics");
  const double fx = k.at("fx"), fy = k.at("fy"), cx = k.at("cx"), cy = k.at("cy");
  const int width = k.at("width"), height = k.at("height");
  double min_depth = 0.0;
  if (truth.contains("sensor") && truth["sensor"].is_object()) {
    min_depth = truth["sensor"].value("min_depth_m", 0.0);
  }
  int n = 0;
  for (const auto& [timestamp, T_W_C] : poses) {
    if (n++ % options.frame_step != 0) continue;
    const Eigen::Vector3d o = T_W_C.translation();
    for (int y = 0; y < height; y += options.pixel_step) {
      for (int x = 0; x < width; x += options.pixel_step) {
        const Eigen::Vector3d ray =
            T_W_C.linear() * Eigen::Vector3d((x - cx) / fx, (y - cy) / fy, 1);
        double nearest = std::numeric_limits<double>::infinity();
        int hit = -1;
        for (std::size_t i = 0; i < planes.size(); ++i) {
          const FramedPlane& p = planes[i].plane;
          const double along = p.normal.dot(ray);
          if (std::abs(along) < 1e-9) continue;
          const double z = (p.offset - p.normal.dot(o)) / along;  // ray z is 1: t is depth
          if (z <= 0.0 || z >= nearest) continue;
          if (!inside(p.uvOf(o + z * ray), planes[i].polygon)) continue;
          nearest = z;
          hit = static_cast<int>(i);
        }
        if (hit < 0 || nearest < min_depth || nearest > options.max_depth_m) continue;
        TruthPlane& target =
            planes[static_cast<std::size_t>(planes[static_cast<std::size_t>(hit)].parent >= 0
                                                ? planes[static_cast<std::size_t>(hit)].parent
                                                : hit)];
        const Eigen::Vector2d cell =
            (target.plane.uvOf(o + nearest * ray) - target.grid_min) / options.cell_m;
        const int c = static_cast<int>(cell.x()), r = static_cast<int>(cell.y());
        if (r >= 0 && c >= 0 && r < target.seen.rows && c < target.seen.cols) {
          target.seen.at<std::uint8_t>(r, c) = 255;
        }
      }
    }
  }
  for (TruthPlane& plane : planes) {
    // Rays are a few centimetres apart at range: close the gaps, keep to the polygon (an
    // overlay's cells lie inside its parent's polygon too).
    cv::morphologyEx(plane.seen, plane.seen, cv::MORPH_CLOSE, cv::Mat::ones(3, 3, CV_8UC1),
                     cv::Point(-1, -1), 1, cv::BORDER_CONSTANT, cv::Scalar(0));
    plane.seen &= plane.in_polygon;
  }
}

std::vector<RunPatch> readPatches(const nlohmann::json& json, const core::Isometry& T_gt_est) {
  if (!json.contains("patches")) throw core::Error("patches file has no \"patches\"");
  // The tiles of one plane (same "plane", one frame) are evaluated as one patch: cutting a
  // large plane into tiles is not a duplicate.
  std::vector<RunPatch> patches;
  std::vector<Eigen::Vector2d> weighted;
  std::vector<double> areas;
  std::map<int, std::size_t> index_of_plane;
  for (const auto& p : json.at("patches")) {
    const int id = p.at("id").get<int>();
    const int plane = p.value("plane", id);
    const auto [it, added] = index_of_plane.try_emplace(plane, patches.size());
    if (added) {
      RunPatch patch;
      patch.id = plane;
      patch.plane = {vec3(p.at("normal")), vec3(p.at("origin")), vec3(p.at("u_axis")),
                     vec3(p.at("v_axis")), p.at("offset_m").get<double>()};
      patches.push_back(std::move(patch));
      weighted.emplace_back(Eigen::Vector2d::Zero());
      areas.push_back(0.0);
    }
    const std::size_t i = it->second;
    for (const auto& part : p.at("outline")) {
      PatchOutline outline{polygonOf(part.at("outer")), {}};
      for (const auto& hole : part.at("holes")) outline.holes.push_back(polygonOf(hole));
      const auto [c, a] = centroidOf(outline.outer);
      weighted[i] += a * c;
      areas[i] += a;
      patches[i].parts.push_back(std::move(outline));
    }
  }
  for (std::size_t i = 0; i < patches.size(); ++i) {
    RunPatch& patch = patches[i];
    const Eigen::Vector2d centroid_uv =
        areas[i] > 0.0 ? Eigen::Vector2d(weighted[i] / areas[i]) : weighted[i];
    patch.centroid_W = T_gt_est * patch.plane.pointAt(centroid_uv);
    patch.normal_W = T_gt_est.linear() * patch.plane.normal;
  }
  return patches;
}

// How many of the patches (their cells on one plane) overlap a larger one by at least
// `min_overlap` of their own cells: each such patch covers the plane a second time.
int countDuplicates(const std::vector<cv::Mat>& cells, double min_overlap) {
  std::vector<int> counts;
  for (const cv::Mat& c : cells) counts.push_back(cv::countNonZero(c));
  int duplicates = 0;
  for (std::size_t a = 0; a < cells.size(); ++a) {
    for (std::size_t b = 0; b < cells.size(); ++b) {
      const bool larger = counts[b] > counts[a] || (counts[b] == counts[a] && b < a);
      if (a == b || !larger) continue;
      if (cv::countNonZero(cells[a] & cells[b]) >= min_overlap * counts[a]) {
        ++duplicates;
        break;
      }
    }
  }
  return duplicates;
}

}  // namespace

PlaneEvaluation evaluatePlanes(const nlohmann::json& truth, const core::Trajectory& truth_poses,
                               const nlohmann::json& patches_json, const core::Isometry& T_gt_est,
                               const PlaneEvaluationOptions& options) {
  std::vector<TruthPlane> planes;
  std::vector<RunPatch> patches;
  try {
    planes = readTruthPlanes(truth, options.cell_m);
    patches = readPatches(patches_json, T_gt_est);
  } catch (const nlohmann::json::exception& e) {
    throw core::Error(fmt::format("malformed plane or patch entry: {}", e.what()));
  }
  findOverlays(planes, options);
  markSeen(planes, truth, truth_poses, options);

  PlaneEvaluation result;
  result.patches = patches.size();
  std::vector<bool> matched(patches.size(), false);
  const core::Isometry T_est_gt = T_gt_est.inverse();
  const double cell_area = options.cell_m * options.cell_m;
  for (const TruthPlane& plane : planes) {
    if (plane.parent >= 0) continue;  // evaluated as part of the plane it lies on
    PlaneResult entry;
    entry.id = plane.id;
    entry.seen_m2 = cv::countNonZero(plane.seen) * cell_area;
    entry.counted = entry.seen_m2 >= options.min_seen_m2;
    std::vector<cv::Mat> on_plane;  // cells of each patch within the duplicate bounds
    for (std::size_t i = 0; i < patches.size(); ++i) {
      const RunPatch& patch = patches[i];
      const double cos_angle = std::min(1.0, std::abs(patch.normal_W.dot(plane.plane.normal)));
      const double angle_deg = std::acos(cos_angle) * 180.0 / M_PI;
      const double offset = std::abs(plane.plane.normal.dot(patch.centroid_W) - plane.plane.offset);
      if (angle_deg > options.duplicate_normal_deg || offset > options.duplicate_offset_m) continue;
      // The patch's cells in this plane's raster.
      cv::Mat covered = cv::Mat::zeros(plane.seen.size(), CV_8UC1);
      for (int r = 0; r < covered.rows; ++r) {
        for (int c = 0; c < covered.cols; ++c) {
          const Eigen::Vector3d X_gt = plane.plane.pointAt(
              plane.grid_min + options.cell_m * Eigen::Vector2d(c + 0.5, r + 0.5));
          if (covers(patch, patch.plane.uvOf(T_est_gt * X_gt)))
            covered.at<std::uint8_t>(r, c) = 255;
        }
      }
      const int covered_cells = cv::countNonZero(covered);
      // Mostly on this plane's polygon, or it is a coplanar neighbour (the other table).
      if (covered_cells == 0 || cv::countNonZero(covered & plane.in_polygon) * 2 < covered_cells) {
        continue;
      }
      on_plane.push_back(covered);
      if (angle_deg > options.max_normal_deg || offset > options.max_offset_m) continue;
      const int both = cv::countNonZero(covered & plane.seen);
      const int either = cv::countNonZero(covered | plane.seen);
      const double iou = either > 0 ? static_cast<double>(both) / either : 0.0;
      if (entry.patch_id < 0 || iou > entry.iou) {
        entry.patch_id = patch.id;
        entry.iou = iou;
        entry.normal_error_deg = angle_deg;
        entry.offset_error_m = offset;
      }
    }
    entry.duplicates = countDuplicates(on_plane, options.min_duplicate_overlap);
    result.duplicate_patches += static_cast<std::size_t>(entry.duplicates);
    if (entry.patch_id >= 0) {
      for (std::size_t i = 0; i < patches.size(); ++i) {
        if (patches[i].id == entry.patch_id) matched[i] = true;
      }
    }
    entry.found = entry.counted && entry.patch_id >= 0 && entry.iou >= options.min_iou;
    result.planes_counted += entry.counted ? 1 : 0;
    result.planes_found += entry.found ? 1 : 0;
    result.planes.push_back(entry);
  }
  result.patches_matched =
      static_cast<std::size_t>(std::count(matched.begin(), matched.end(), true));
  result.recall = result.planes_counted > 0 ? static_cast<double>(result.planes_found) /
                                                  static_cast<double>(result.planes_counted)
                                            : 0.0;
  result.precision = result.patches > 0 ? static_cast<double>(result.patches_matched) /
                                              static_cast<double>(result.patches)
                                        : 0.0;
  return result;
}

}  // namespace tessera::eval
