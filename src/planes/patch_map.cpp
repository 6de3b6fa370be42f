#include "tessera/planes/patch_map.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <Eigen/Geometry>
#include <opencv2/imgproc.hpp>

#include "tessera/planes/exposure.h"

namespace tessera::planes {

std::vector<PlaneObservation> observationsOf(const core::Frame& frame,
                                             const PlaneDetection& detection,
                                             const core::Isometry& T_W_C) {
  const core::Intrinsics& k = frame.intrinsics;
  std::vector<PlaneObservation> observations(detection.planes.size());
  const int step = detection.scale;
  for (int v = 0; v < detection.labels.rows; ++v) {
    const auto* label = detection.labels.ptr<std::uint8_t>(v);
    const auto* depth = frame.depth_mm.ptr<std::uint16_t>(v * step);
    for (int u = 0; u < detection.labels.cols; ++u) {
      if (label[u] >= observations.size()) continue;
      const double z = depth[u * step] * 1e-3;
      const Eigen::Vector3d X_C((u * step - k.cx) * z / k.fx, (v * step - k.cy) * z / k.fy, z);
      observations[label[u]].points_W.push_back(T_W_C * X_C);
    }
  }
  return observations;
}

Patch::Frame Patch::planeFrame() const {
  Frame frame;
  frame.origin = origin + (offset - normal.dot(origin)) * normal;
  frame.u_axis = (u_axis - u_axis.dot(normal) * normal).normalized();
  frame.v_axis = normal.cross(frame.u_axis);
  return frame;
}

Cell Patch::cellOf(const Eigen::Vector3d& X_W, double cell_m) const {
  const Eigen::Vector3d d = X_W - origin;
  return {static_cast<int>(std::floor(d.dot(u_axis) / cell_m)),
          static_cast<int>(std::floor(d.dot(v_axis) / cell_m))};
}

Eigen::Vector3d Patch::cellCentre(const Cell& cell, double cell_m) const {
  return origin + (cell.first + 0.5) * cell_m * u_axis + (cell.second + 0.5) * cell_m * v_axis;
}

double PatchMap::areaM2(const Patch& patch) const {
  return static_cast<double>(patch.cells.size()) * config_.cell_m * config_.cell_m;
}

bool PatchMap::continues(const Patch& patch, const PlaneFit& region,
                         const std::vector<Eigen::Vector3d>& points) const {
  // Planes are compared as unoriented: a region seen from the other side is the same plane.
  const double cos_angle = std::abs(patch.normal.dot(region.normal));
  if (cos_angle < std::cos(config_.max_normal_angle_deg * M_PI / 180.0)) return false;
  // The region's centroid must lie near the patch's plane. (Comparing plane offsets instead
  // would magnify a small tilt by the distance from the world origin.)
  if (std::abs(patch.normal.dot(region.centroid) - patch.offset) > config_.max_offset_m) {
    return false;
  }
  // Touching: a point falls in or next to an occupied cell. Points come in raster order, so
  // a point in the same cell as the one before adds nothing.
  Cell last{std::numeric_limits<int>::min(), 0};
  for (const auto& X : points) {
    const Cell c = patch.cellOf(X, config_.cell_m);
    if (c == last) continue;
    last = c;
    for (int du = -1; du <= 1; ++du) {
      for (int dv = -1; dv <= 1; ++dv) {
        if (patch.cells.count({c.first + du, c.second + dv}) > 0) return true;
      }
    }
  }
  return false;
}

void PatchMap::addObservation(Patch& patch, const std::vector<Eigen::Vector3d>& points,
                              const PointMoments& moments) const {
  Cell last{std::numeric_limits<int>::min(), 0};
  for (const auto& X : points) {
    const Cell c = patch.cellOf(X, config_.cell_m);
    if (c != last) patch.cells.insert(c);
    last = c;
  }
  patch.moments.add(moments);
  refit(patch);
}

void PatchMap::refit(Patch& patch) {
  const PlaneFit plane = fitPlane(patch.moments);
  // Keep the orientation the patch was created with.
  const double sign = plane.normal.dot(patch.normal) < 0.0 ? -1.0 : 1.0;
  patch.normal = sign * plane.normal;
  patch.offset = sign * plane.offset;
}

void PatchMap::absorb(Patch& into, const Patch& other) const {
  for (const Cell& cell : other.cells) {
    into.cells.insert(into.cellOf(other.cellCentre(cell, config_.cell_m), config_.cell_m));
  }
  // Samples move into the kept patch's plane frame.
  for (ColourSample sample : other.samples.all()) {
    const Eigen::Vector3d X = other.origin + sample.u * other.u_axis + sample.v * other.v_axis;
    sample.u = static_cast<float>((X - into.origin).dot(into.u_axis));
    sample.v = static_cast<float>((X - into.origin).dot(into.v_axis));
    into.samples.add(sample);
  }
  into.footprint_sum_m += other.footprint_sum_m;
  into.footprint_pixels += other.footprint_pixels;
  into.log_gain_sum += other.log_gain_sum;
  into.moments.add(other.moments);
  refit(into);
}

std::vector<int> PatchMap::add(const std::vector<PlaneObservation>& observations) {
  std::vector<int> ids;
  for (const PlaneObservation& observation : observations) {
    if (observation.points_W.size() < 3) {
      ids.push_back(-1);
      continue;
    }
    PointMoments moments;
    for (const auto& X : observation.points_W) moments.add(X);
    const PlaneFit plane = fitPlane(moments);
    std::vector<std::size_t> matches;
    for (std::size_t i = 0; i < patches_.size(); ++i) {
      if (continues(patches_[i], plane, observation.points_W)) {
        matches.push_back(i);
      }
    }
    if (matches.empty()) {
      Patch patch;
      patch.id = next_id_++;
      patch.normal = plane.normal;
      patch.offset = plane.offset;
      patch.origin = plane.centroid;
      patch.u_axis = plane.major_axis;  // eigenvectors: already orthogonal to the normal
      patch.v_axis = plane.normal.cross(patch.u_axis);
      patch.samples = ColourSamples(config_.sample_cell_m);
      addObservation(patch, observation.points_W, moments);
      patches_.push_back(std::move(patch));
      ids.push_back(patches_.back().id);
      seen_this_frame_.insert(patches_.back().id);
      continue;
    }
    // The region joins every patch it continues: they were parts of one plane.
    Patch& kept = patches_[matches.front()];
    for (std::size_t m = matches.size(); m-- > 1;) {
      absorb(kept, patches_[matches[m]]);
    }
    addObservation(kept, observation.points_W, moments);
    const int kept_id = kept.id;
    for (std::size_t m = matches.size(); m-- > 1;) {
      const Patch& gone = patches_[matches[m]];
      if (gone.version > 0) pending_.push_back({PatchEvent::Kind::kRetired, gone.id, gone.version});
      seen_this_frame_.erase(gone.id);
      // Ids already handed out for this frame's earlier regions now live on in the kept patch.
      std::replace(ids.begin(), ids.end(), gone.id, kept_id);
      patches_.erase(patches_.begin() + static_cast<std::ptrdiff_t>(matches[m]));
    }
    ids.push_back(kept_id);
    seen_this_frame_.insert(kept_id);
  }
  return ids;
}

namespace {

// Per region of a frame: its patch's plane in the camera frame (n_C . X_C = d_C) and the
// camera-frame position and axes of the patch's (u, v) frame, so each pixel costs a few
// multiplies.
struct ColourTarget {
  Patch* patch = nullptr;
  Eigen::Vector3f n_C, origin_C, u_C, v_C;
  float d_C = 0.0F;
};

// What pass one learns of a pixel that sees its patch: where its ray meets the plane, its view
// weight and its distance.
struct PlanePixel {
  float u = 0.0F, v = 0.0F, weight = 0.0F, distance = 0.0F;
};

// Whether the colour around (x, y) is nearly uniform: only there does a pixel compared with
// what the patch holds at its position measure exposure, not a few millimetres of
// misregistration across an edge.
bool smooth(const cv::Mat& rgb, int x, int y) {
  constexpr int kMaxStep = 12;  // grey levels between the pixels two apart, any channel
  if (x < 2 || y < 2 || x + 2 >= rgb.cols || y + 2 >= rgb.rows) return false;
  const cv::Vec3b& c = rgb.at<cv::Vec3b>(y, x);
  for (const auto& [dx, dy] : {std::pair{-2, 0}, {2, 0}, {0, -2}, {0, 2}}) {
    const cv::Vec3b& n = rgb.at<cv::Vec3b>(y + dy, x + dx);
    for (int ch = 0; ch < 3; ++ch) {
      if (std::abs(static_cast<int>(n[ch]) - static_cast<int>(c[ch])) > kMaxStep) return false;
    }
  }
  return true;
}

}  // namespace

std::optional<Eigen::Vector3f> PatchMap::addColours(const core::Frame& frame,
                                                    const PlaneDetection& detection,
                                                    const core::Isometry& T_W_C,
                                                    const std::vector<int>& ids, double sharpness) {
  const core::Intrinsics& k = frame.intrinsics;
  if (frame.colour_camera || frame.rgb.type() != CV_8UC3 || frame.rgb.cols != k.width ||
      frame.rgb.rows != k.height || frame.depth_mm.size() != frame.rgb.size()) {
    return std::nullopt;  // colour not registered pixel for pixel to depth
  }
  const core::Isometry T_C_W = T_W_C.inverse();
  std::vector<ColourTarget> targets(ids.size());
  bool any = false;
  for (std::size_t r = 0; r < ids.size(); ++r) {
    auto it = std::find_if(patches_.begin(), patches_.end(),
                           [&](const Patch& p) { return p.id == ids[r]; });
    if (it == patches_.end()) continue;
    ColourTarget& target = targets[r];
    target.patch = &*it;
    target.n_C = (T_C_W.linear() * it->normal).cast<float>();
    target.d_C = static_cast<float>(it->offset - it->normal.dot(T_W_C.translation()));
    target.origin_C = (T_C_W * it->origin).cast<float>();
    target.u_C = (T_C_W.linear() * it->u_axis).cast<float>();
    target.v_C = (T_C_W.linear() * it->v_axis).cast<float>();
    any = true;
  }
  if (!any) return std::nullopt;

  // Pass one: the pixels whose measured depth confirms their patch's plane.
  const int scale = detection.scale;
  cv::Mat sees_plane = cv::Mat::zeros(frame.rgb.size(), CV_8UC1);
  cv::Mat plane_pixels(frame.rgb.size(), CV_32FC4);
  const auto tolerance_m = static_cast<float>(config_.colour_depth_tolerance_m);
  const auto tolerance_per_m2 = static_cast<float>(config_.colour_depth_tolerance_per_m2);
  for (int y = 0; y < frame.rgb.rows; ++y) {
    const auto* label = detection.labels.ptr<std::uint8_t>(y / scale);
    const auto* depth = frame.depth_mm.ptr<std::uint16_t>(y);
    auto* sees = sees_plane.ptr<std::uint8_t>(y);
    auto* out = plane_pixels.ptr<PlanePixel>(y);
    const auto ray_y = static_cast<float>((y - k.cy) / k.fy);
    for (int x = 0; x < frame.rgb.cols; ++x) {
      const std::uint8_t l = label[x / scale];
      if (l >= targets.size() || targets[l].patch == nullptr || depth[x] == 0) continue;
      const ColourTarget& target = targets[l];
      const Eigen::Vector3f ray(static_cast<float>((x - k.cx) / k.fx), ray_y, 1.0F);
      const float along = target.n_C.dot(ray);
      if (std::abs(along) < 1e-6F) continue;
      const float z = target.d_C / along;  // the ray meets the plane at depth z
      if (z <= 0.0F) continue;
      const float measured = static_cast<float>(depth[x]) * 1e-3F;
      if (std::abs(measured - z) > tolerance_m + tolerance_per_m2 * z * z) continue;
      const Eigen::Vector3f offset = z * ray - target.origin_C;
      const float ray_norm = ray.norm();
      const float distance = z * ray_norm;
      out[x] = {offset.dot(target.u_C), offset.dot(target.v_C),
                std::abs(along) / ray_norm / (distance * distance), distance};
      sees[x] = 255;
    }
  }
  if (const int margin = config_.colour_edge_margin_px; margin > 0) {
    cv::erode(sees_plane, sees_plane,
              cv::getStructuringElement(cv::MORPH_RECT, cv::Size(2 * margin + 1, 2 * margin + 1)));
  }

  // The frame's gain against what the patches hold (every 2nd pixel each way is plenty).
  Eigen::Vector3f gain = Eigen::Vector3f::Ones();
  if (config_.exposure_compensation) {
    std::vector<ColourPair> pairs;
    for (int y = 0; y < frame.rgb.rows; y += 2) {
      const auto* label = detection.labels.ptr<std::uint8_t>(y / scale);
      const auto* sees = sees_plane.ptr<std::uint8_t>(y);
      const auto* rgb = frame.rgb.ptr<cv::Vec3b>(y);
      const auto* pixel = plane_pixels.ptr<PlanePixel>(y);
      for (int x = 0; x < frame.rgb.cols; x += 2) {
        if (sees[x] == 0 || !smooth(frame.rgb, x, y)) continue;
        const auto held = targets[label[x / scale]].patch->samples.colourAt(pixel[x].u, pixel[x].v);
        if (held) pairs.push_back({Eigen::Vector3f(rgb[x][0], rgb[x][1], rgb[x][2]), *held});
      }
    }
    if (const auto estimated = estimateGain(pairs)) last_gain_ = *estimated;
    gain = last_gain_;
  }

  // Pass two: the samples, weighted by their view and the frame's sharpness.
  const auto frame_weight = static_cast<float>(std::max(sharpness, 1e-6));
  std::vector<std::size_t> pixels_of(targets.size(), 0);
  std::vector<double> distance_of(targets.size(), 0.0);
  for (int y = 0; y < frame.rgb.rows; ++y) {
    const auto* label = detection.labels.ptr<std::uint8_t>(y / scale);
    const auto* sees = sees_plane.ptr<std::uint8_t>(y);
    const auto* rgb = frame.rgb.ptr<cv::Vec3b>(y);
    const auto* pixel = plane_pixels.ptr<PlanePixel>(y);
    for (int x = 0; x < frame.rgb.cols; ++x) {
      if (sees[x] == 0) continue;
      const std::uint8_t l = label[x / scale];
      std::array<std::uint8_t, 3> colour;
      for (int c = 0; c < 3; ++c) {
        colour[static_cast<std::size_t>(c)] =
            cv::saturate_cast<std::uint8_t>(gain[c] * static_cast<float>(rgb[x][c]));
      }
      targets[l].patch->samples.add(pixel[x].u, pixel[x].v, colour, pixel[x].weight * frame_weight);
      ++pixels_of[l];
      distance_of[l] += pixel[x].distance;
    }
  }
  const Eigen::Vector3d log_gain = gain.cast<double>().array().log();
  bool sampled = false;
  for (std::size_t l = 0; l < targets.size(); ++l) {
    if (pixels_of[l] == 0) continue;
    Patch& patch = *targets[l].patch;
    patch.footprint_sum_m += distance_of[l] / k.fx;
    patch.footprint_pixels += pixels_of[l];
    patch.log_gain_sum += static_cast<double>(pixels_of[l]) * log_gain;
    sampled = true;
  }
  if (!sampled) return std::nullopt;
  return gain;
}

PatchSnapshot PatchMap::snapshot(const Patch& patch) const {
  PatchSnapshot snapshot;
  snapshot.id = patch.id;
  snapshot.version = patch.version;
  snapshot.normal = patch.normal;
  snapshot.offset = patch.offset;
  snapshot.frame = patch.planeFrame();
  snapshot.outline = outlineOf(patch);
  snapshot.samples = patch.samples.all();
  if (patch.footprint_pixels > 0 && !patch.log_gain_sum.isZero()) {
    // Samples were compensated to the first frame's exposure; the mean exposure of the frames
    // that coloured the patch fits its views best.
    const Eigen::Vector3d back =
        (-patch.log_gain_sum / static_cast<double>(patch.footprint_pixels)).array().exp();
    for (ColourSample& sample : snapshot.samples) {
      for (int c = 0; c < 3; ++c) {
        const auto i = static_cast<std::size_t>(c);
        sample.rgb[i] = cv::saturate_cast<std::uint8_t>(back[c] * sample.rgb[i]);
      }
    }
  }
  if (patch.footprint_pixels > 0) {
    snapshot.pixel_footprint_m =
        patch.footprint_sum_m / static_cast<double>(patch.footprint_pixels);
  }
  return snapshot;
}

void PatchMap::finalize(Patch& patch, std::vector<PatchEvent>& events) const {
  patch.version += 1;
  patch.finalized = true;
  patch.finalized_area_m2 = areaM2(patch);
  events.push_back(
      {PatchEvent::Kind::kFinalized, patch.id, patch.version, patch.finalized_area_m2});
}

std::vector<PatchEvent> PatchMap::endFrame(long frame_index) {
  std::vector<PatchEvent> events = std::move(pending_);
  pending_.clear();
  for (Patch& patch : patches_) {
    const double area = areaM2(patch);
    if (seen_this_frame_.count(patch.id) == 0) {
      const bool gone_long = frame_index - patch.last_seen_frame >= config_.out_of_view_frames;
      if (!patch.finalized && gone_long && area >= config_.min_area_m2) finalize(patch, events);
      continue;
    }
    patch.last_seen_frame = frame_index;
    patch.frames_seen += 1;
    patch.area_in_view.push_back(area);
    while (patch.area_in_view.size() > static_cast<std::size_t>(config_.stable_frames) + 1) {
      patch.area_in_view.pop_front();
    }
    if (patch.finalized && area > patch.finalized_area_m2 * (1.0 + config_.max_growth)) {
      patch.finalized = false;  // it grows again: a new version will follow
    }
    const bool stable =
        patch.area_in_view.size() > static_cast<std::size_t>(config_.stable_frames) &&
        area <= patch.area_in_view.front() * (1.0 + config_.max_growth);
    if (!patch.finalized && stable && area >= config_.min_area_m2) finalize(patch, events);
  }
  seen_this_frame_.clear();
  return events;
}

std::vector<PatchEvent> PatchMap::finalizeAll() {
  std::vector<PatchEvent> events = std::move(pending_);
  pending_.clear();
  for (Patch& patch : patches_) {
    if (!patch.finalized && areaM2(patch) >= config_.min_area_m2) finalize(patch, events);
  }
  return events;
}

const Patch* PatchMap::find(int id) const {
  for (const Patch& patch : patches_) {
    if (patch.id == id) return &patch;
  }
  return nullptr;
}

std::size_t PatchMap::liveCount() const {
  return static_cast<std::size_t>(
      std::count_if(patches_.begin(), patches_.end(), [](const Patch& p) { return !p.finalized; }));
}

std::size_t PatchMap::finalizedCount() const { return patches_.size() - liveCount(); }

}  // namespace tessera::planes
