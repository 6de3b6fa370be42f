// PatchMap::addColours: colour samples from one frame for the patches its regions went to
// (docs/MEASUREMENTS.md, "Textures: bitmaps of the finalized patches").
#include <algorithm>
#include <cmath>
#include <optional>
#include <vector>

#include <opencv2/imgproc.hpp>

#include "tessera/planes/exposure.h"
#include "tessera/planes/patch_map.h"

namespace tessera::planes {

namespace {

// A plane in the colour camera's frame at the colour image's time: n_C . X_C = d_C, and the
// camera-frame origin and axes of the plane's (u, v) frame.
struct ColourPlane {
  Eigen::Vector3f n_C;
  float d_C = 0.0F;
  Eigen::Vector3f origin_C, u_C, v_C;
};

// One tile of a region's plane, and what this frame gave it.
struct TileTarget {
  Cell key;
  Patch* patch = nullptr;
  std::size_t pixels = 0;
  double distance_sum = 0.0;
};

// Per region of a frame: its patch's plane in the camera frame (n_C . X_C = d_C), the
// camera-frame position and axes of the plane's (u, v) frame, so each pixel costs a few
// multiplies, and the plane's tiles a pixel's colour can go to.
struct ColourTarget {
  std::vector<TileTarget> tiles;  // a plane not cut has one
  TileGrid grid;
  double cell_m = 0.0;
  Eigen::Vector3f n_C, origin_C, u_C, v_C;
  float d_C = 0.0F;
  std::optional<ColourPlane> colour_plane;  // where colour was taken at another time

  // The tile where the plane point (u, v) lies; none where the plane has no tile yet, or the
  // tile's samples are out of memory.
  TileTarget* tileAt(float u, float v) {
    if (!grid.cut()) return &tiles.front();
    const Cell key = grid.keyOf(
        {static_cast<int>(std::floor(u / cell_m)), static_cast<int>(std::floor(v / cell_m))});
    for (TileTarget& tile : tiles) {
      if (tile.key == key) return &tile;
    }
    return nullptr;
  }
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

// Where `ray` (a pixel's, z = 1) meets the target's plane, when the measured depth confirms it
// within `tolerance_m` + `tolerance_per_m2` z^2: its (u, v) (along the colour's own ray at its
// own time, where that differs), view weight |cos| / distance^2 and distance.
std::optional<PlanePixel> hitPlane(const ColourTarget& target, const Eigen::Vector3f& ray,
                                   float measured, float tolerance_m, float tolerance_per_m2) {
  const float along = target.n_C.dot(ray);
  if (std::abs(along) < 1e-6F) return std::nullopt;
  const float z = target.d_C / along;  // the ray meets the plane at depth z
  if (z <= 0.0F) return std::nullopt;
  if (std::abs(measured - z) > tolerance_m + tolerance_per_m2 * z * z) return std::nullopt;
  Eigen::Vector3f offset = z * ray - target.origin_C;
  const float ray_norm = ray.norm();
  const float distance = z * ray_norm;
  Eigen::Vector2f uv(offset.dot(target.u_C), offset.dot(target.v_C));
  if (const auto& at = target.colour_plane) {
    // The same pixel of the colour image looked along its ray at the colour's own time.
    const float along_colour = at->n_C.dot(ray);
    if (std::abs(along_colour) < 1e-6F) return std::nullopt;
    offset = (at->d_C / along_colour) * ray - at->origin_C;
    uv = {offset.dot(at->u_C), offset.dot(at->v_C)};
  }
  return PlanePixel{uv.x(), uv.y(), std::abs(along) / ray_norm / (distance * distance), distance};
}

// Whether the rectangle of `plane`'s cells can show inside `box` (pixels) to the camera at
// T_C_W: the bounding box of its corners' projections holds all it covers. A rectangle that
// reaches behind the camera may show anywhere, so it counts.
bool boundsMayMeet(const Plane& plane, double cell_m, const core::Isometry& T_C_W,
                   const core::Intrinsics& k, const cv::Rect& box) {
  const PlaneGeometry& g = *plane.geometry;
  const double u[2] = {plane.lo.first * cell_m, (plane.hi.first + 1) * cell_m};
  const double v[2] = {plane.lo.second * cell_m, (plane.hi.second + 1) * cell_m};
  double x_lo = INFINITY, x_hi = -INFINITY, y_lo = INFINITY, y_hi = -INFINITY;
  for (const double cu : u) {
    for (const double cv : v) {
      const Eigen::Vector3d X_C = T_C_W * (g.origin + cu * g.u_axis + cv * g.v_axis);
      if (X_C.z() < 1e-3) return true;
      const double x = k.fx * X_C.x() / X_C.z() + k.cx;
      const double y = k.fy * X_C.y() / X_C.z() + k.cy;
      x_lo = std::min(x_lo, x), x_hi = std::max(x_hi, x);
      y_lo = std::min(y_lo, y), y_hi = std::max(y_hi, y);
    }
  }
  return x_hi >= box.x && x_lo <= box.x + box.width && y_hi >= box.y && y_lo <= box.y + box.height;
}

}  // namespace

std::optional<Eigen::Vector3f> PatchMap::addColours(
    const core::Frame& frame, const PlaneDetection& detection, const core::Isometry& T_W_C,
    const std::vector<int>& ids, double sharpness,
    const std::optional<core::Isometry>& T_W_C_colour) {
  const core::Intrinsics& k = frame.intrinsics;
  if (frame.colour_camera || frame.rgb.type() != CV_8UC3 || frame.rgb.cols != k.width ||
      frame.rgb.rows != k.height || frame.depth_mm.size() != frame.rgb.size()) {
    return std::nullopt;  // colour not registered pixel for pixel to depth
  }
  const core::Isometry T_C_W = T_W_C.inverse();
  const core::Isometry T_Cc_W = T_W_C_colour.value_or(T_W_C).inverse();
  // The target of `plane`, over the tiles `take` accepts; false when it has none.
  const auto makeTarget = [&](const Plane& plane, ColourTarget& target, auto take) {
    for (Patch* tile : tilesOf(plane)) {
      if (!tile->spilled_samples && take(*tile)) target.tiles.push_back({tile->tile, tile});
    }
    if (target.tiles.empty()) return false;
    const PlaneGeometry& geometry = *plane.geometry;
    target.grid = plane.grid;
    target.cell_m = config_.cell_m;
    target.n_C = (T_C_W.linear() * geometry.normal).cast<float>();
    target.d_C = static_cast<float>(geometry.offset - geometry.normal.dot(T_W_C.translation()));
    target.origin_C = (T_C_W * geometry.origin).cast<float>();
    target.u_C = (T_C_W.linear() * geometry.u_axis).cast<float>();
    target.v_C = (T_C_W.linear() * geometry.v_axis).cast<float>();
    if (T_W_C_colour) {
      target.colour_plane = ColourPlane{
          (T_Cc_W.linear() * geometry.normal).cast<float>(),
          static_cast<float>(geometry.offset - geometry.normal.dot(T_W_C_colour->translation())),
          (T_Cc_W * geometry.origin).cast<float>(),
          (T_Cc_W.linear() * geometry.u_axis).cast<float>(),
          (T_Cc_W.linear() * geometry.v_axis).cast<float>()};
    }
    return true;
  };
  std::vector<ColourTarget> targets(ids.size());
  bool any = false;
  for (std::size_t r = 0; r < ids.size(); ++r) {
    const Patch* region = find(ids[r]);
    if (region == nullptr) continue;
    any =
        makeTarget(planes_.at(region->plane), targets[r], [](const Patch&) { return true; }) || any;
  }
  if (!any) return std::nullopt;
  // Planes near a region's own, within colour_neighbour_angle_deg and _offset_m (one surface
  // fitted twice, as noisy depth does): the region's pixels also colour their growing tiles
  // where the depth confirms them, so that each gets every view of the surface. Only planes
  // whose cells can be in the region's box count: a floor is near every other floor of the map.
  const int scale = detection.scale;
  const int margin = std::max(config_.colour_edge_margin_px, 0);
  struct Neighbour {
    std::uint8_t region = 0;
    ColourTarget target;
    cv::Rect area;  // the region's box and the edge margin, in the frame: sees and pixels
    cv::Mat sees, pixels;
  };
  std::vector<Neighbour> neighbours;
  if (config_.colour_neighbour_angle_deg > 0.0) {
    const double min_cos = std::cos(config_.colour_neighbour_angle_deg * M_PI / 180.0);
    const cv::Rect image(0, 0, frame.rgb.cols, frame.rgb.rows);
    for (std::size_t r = 0; r < ids.size() && r < 255; ++r) {
      if (targets[r].tiles.empty()) continue;
      const cv::Rect low = cv::boundingRect(detection.labels == static_cast<int>(r));
      const cv::Rect box =
          cv::Rect(low.x * scale, low.y * scale, low.width * scale, low.height * scale) & image;
      if (box.empty()) continue;
      const Plane& own = planes_.at(find(ids[r])->plane);
      for (const auto& [id, plane] : planes_) {
        if (id == own.id || set_aside_.count(id) > 0 || !plane.has_cells) continue;
        const PlaneGeometry& g = *plane.geometry;
        if (g.normal.dot(own.geometry->normal) < min_cos ||
            std::abs(g.normal.dot(own.geometry->origin) - g.offset) >
                config_.colour_neighbour_offset_m ||
            !boundsMayMeet(plane, config_.cell_m, T_C_W, k, box)) {
          continue;
        }
        Neighbour neighbour;
        neighbour.region = static_cast<std::uint8_t>(r);
        neighbour.area = cv::Rect(box.x - margin, box.y - margin, box.width + 2 * margin,
                                  box.height + 2 * margin) &
                         image;
        if (makeTarget(plane, neighbour.target,
                       [](const Patch& tile) { return !tile.finalized; })) {
          neighbours.push_back(std::move(neighbour));
        }
      }
    }
  }

  // Pass one: the pixels whose measured depth confirms their patch's plane. The label of pixel
  // column x is in column x / scale, looked up rather than divided for every pixel; the
  // pixels' buffer (5 MB at 640x480) is kept from frame to frame rather than mapped afresh.
  std::vector<int> label_column(static_cast<std::size_t>(frame.rgb.cols));
  for (int x = 0; x < frame.rgb.cols; ++x) label_column[static_cast<std::size_t>(x)] = x / scale;
  const int* column = label_column.data();
  cv::Mat sees_plane = cv::Mat::zeros(frame.rgb.size(), CV_8UC1);
  thread_local cv::Mat plane_pixels;
  plane_pixels.create(frame.rgb.size(), CV_32FC4);
  const auto tolerance_m = static_cast<float>(config_.colour_depth_tolerance_m);
  const auto tolerance_per_m2 = static_cast<float>(config_.colour_depth_tolerance_per_m2);
  const auto hit = [&](const ColourTarget& target, const Eigen::Vector3f& ray, float measured) {
    return hitPlane(target, ray, measured, tolerance_m, tolerance_per_m2);
  };
  for (int y = 0; y < frame.rgb.rows; ++y) {
    const auto* label = detection.labels.ptr<std::uint8_t>(y / scale);
    const auto* depth = frame.depth_mm.ptr<std::uint16_t>(y);
    auto* sees = sees_plane.ptr<std::uint8_t>(y);
    auto* out = plane_pixels.ptr<PlanePixel>(y);
    const auto ray_y = static_cast<float>((y - k.cy) / k.fy);
    for (int x = 0; x < frame.rgb.cols; ++x) {
      const std::uint8_t l = label[column[x]];
      if (l >= targets.size() || targets[l].tiles.empty() || depth[x] == 0) continue;
      const Eigen::Vector3f ray(static_cast<float>((x - k.cx) / k.fx), ray_y, 1.0F);
      const auto pixel = hit(targets[l], ray, static_cast<float>(depth[x]) * 1e-3F);
      if (!pixel) continue;
      out[x] = *pixel;
      sees[x] = 255;
    }
  }
  // ... and, for each neighbouring plane, the pixels of its region that confirm it inside its
  // occupied cells (a neighbour none confirms is dropped).
  const auto cell = static_cast<float>(config_.cell_m);
  for (Neighbour& neighbour : neighbours) {
    const cv::Rect& area = neighbour.area;
    neighbour.sees = cv::Mat::zeros(area.size(), CV_8UC1);
    neighbour.pixels.create(area.size(), CV_32FC4);
    bool confirmed = false;
    for (int y = area.y; y < area.y + area.height; ++y) {
      const auto* label = detection.labels.ptr<std::uint8_t>(y / scale);
      const auto* depth = frame.depth_mm.ptr<std::uint16_t>(y);
      auto* sees = neighbour.sees.ptr<std::uint8_t>(y - area.y);
      auto* out = neighbour.pixels.ptr<PlanePixel>(y - area.y);
      const auto ray_y = static_cast<float>((y - k.cy) / k.fy);
      for (int x = area.x; x < area.x + area.width; ++x) {
        if (label[column[x]] != neighbour.region || depth[x] == 0) continue;
        const Eigen::Vector3f ray(static_cast<float>((x - k.cx) / k.fx), ray_y, 1.0F);
        const auto pixel = hit(neighbour.target, ray, static_cast<float>(depth[x]) * 1e-3F);
        if (!pixel) continue;
        const TileTarget* tile = neighbour.target.tileAt(pixel->u, pixel->v);
        if (tile == nullptr ||
            tile->patch->cells.count(Cell{static_cast<int>(std::floor(pixel->u / cell)),
                                          static_cast<int>(std::floor(pixel->v / cell))}) == 0) {
          continue;
        }
        out[x - area.x] = *pixel;
        sees[x - area.x] = 255;
        confirmed = true;
      }
    }
    if (!confirmed) neighbour.sees.release();
  }
  std::erase_if(neighbours, [](const Neighbour& n) { return n.sees.empty(); });
  if (margin > 0) {
    // Each neighbour's area reaches `margin` beyond its region's box (or to the frame's edge),
    // so eroding it alone removes what eroding the whole frame would.
    const cv::Mat square =
        cv::getStructuringElement(cv::MORPH_RECT, cv::Size(2 * margin + 1, 2 * margin + 1));
    cv::erode(sees_plane, sees_plane, square);
    for (Neighbour& neighbour : neighbours) cv::erode(neighbour.sees, neighbour.sees, square);
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
        const TileTarget* tile = targets[label[column[x]]].tileAt(pixel[x].u, pixel[x].v);
        if (tile == nullptr) continue;
        const auto held = tile->patch->samples->colourAt(pixel[x].u, pixel[x].v);
        if (held) pairs.push_back({Eigen::Vector3f(rgb[x][0], rgb[x][1], rgb[x][2]), *held});
      }
    }
    if (const auto estimated = estimateGain(pairs)) last_gain_ = *estimated;
    gain = last_gain_;
  }

  // Pass two: the samples, weighted by their view and the frame's sharpness. Each pixel's cell
  // is located (and its memory fetched) kAhead pixels before it is blended, in the same order:
  // the blends wait on memory far less, and every cell sees them as add() one by one would.
  const auto frame_weight = static_cast<float>(std::max(sharpness, 1e-6));
  const auto view = static_cast<std::int32_t>(frame.index);
  struct Pending {
    ColourSamples* samples = nullptr;
    ColourSamples::Slot slot;
    std::array<std::uint8_t, 3> colour{};
    float weight = 0.0F;
  };
  constexpr std::size_t kAhead = 16;
  std::array<Pending, kAhead> pending;
  std::size_t queued = 0;  // pixels located; those before queued - kAhead are blended
  const auto blendPixel = [&](std::size_t i) {
    const Pending& at = pending[i % kAhead];
    at.samples->blend(at.slot, at.colour, at.weight);
  };
  const auto addSample = [&](TileTarget* tile, const PlanePixel& pixel, const cv::Vec3b& rgb) {
    if (tile == nullptr) return;
    if (queued >= kAhead) blendPixel(queued - kAhead);
    Pending& next = pending[queued % kAhead];
    ++queued;
    for (int c = 0; c < 3; ++c) {
      next.colour[static_cast<std::size_t>(c)] =
          cv::saturate_cast<std::uint8_t>(gain[c] * static_cast<float>(rgb[c]));
    }
    next.samples = &tile->patch->samples.edit();
    next.slot = next.samples->locate(pixel.u, pixel.v, view);
    next.weight = pixel.weight * frame_weight;
    ++tile->pixels;
    tile->distance_sum += pixel.distance;
  };
  for (int y = 0; y < frame.rgb.rows; ++y) {
    const auto* label = detection.labels.ptr<std::uint8_t>(y / scale);
    const auto* sees = sees_plane.ptr<std::uint8_t>(y);
    const auto* rgb = frame.rgb.ptr<cv::Vec3b>(y);
    const auto* pixel = plane_pixels.ptr<PlanePixel>(y);
    for (int x = 0; x < frame.rgb.cols; ++x) {
      if (sees[x] == 0) continue;
      addSample(targets[label[column[x]]].tileAt(pixel[x].u, pixel[x].v), pixel[x], rgb[x]);
    }
  }
  for (Neighbour& neighbour : neighbours) {
    const cv::Rect& area = neighbour.area;
    for (int y = area.y; y < area.y + area.height; ++y) {
      const auto* sees = neighbour.sees.ptr<std::uint8_t>(y - area.y);
      const auto* rgb = frame.rgb.ptr<cv::Vec3b>(y);
      const auto* pixel = neighbour.pixels.ptr<PlanePixel>(y - area.y);
      for (int x = area.x; x < area.x + area.width; ++x) {
        const PlanePixel& at = pixel[x - area.x];
        if (sees[x - area.x] != 0) addSample(neighbour.target.tileAt(at.u, at.v), at, rgb[x]);
      }
    }
    targets.push_back(std::move(neighbour.target));  // settled with the regions' own below
  }
  for (std::size_t i = queued - std::min(queued, kAhead); i < queued; ++i) blendPixel(i);
  const Eigen::Vector3d log_gain = gain.cast<double>().array().log();
  bool sampled = false;
  for (ColourTarget& target : targets) {
    for (TileTarget& tile : target.tiles) {
      if (tile.pixels == 0) continue;
      Patch& patch = *tile.patch;
      patch.samples.edit().settle();
      patch.footprint_sum_m += tile.distance_sum / k.fx;
      patch.footprint_pixels += tile.pixels;
      patch.log_gain_sum += static_cast<double>(tile.pixels) * log_gain;
      sampled = true;
    }
  }
  if (!sampled) return std::nullopt;
  return gain;
}

}  // namespace tessera::planes
