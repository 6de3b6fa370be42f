// composeByViews: regions, their candidate views, the labelling, levelling and the feathered
// composite (include/tessera/texture/view_selection.h has the method).
#include <algorithm>
#include <cmath>
#include <map>
#include <unordered_map>

#include <Eigen/SparseCholesky>
#include <Eigen/SparseCore>

#include "tessera/texture/view_selection.h"

namespace tessera::texture {

namespace {

using planes::ColourSample;

constexpr double kMaxLogGain = 0.4;  // a view's gain stays within e^±0.4 = 0.67 to 1.49
// A region's levelling offset stays within this many grey levels: two views of one surface
// differ by light and exposure, not by what colour it is.
constexpr double kMaxOffset = 30.0;

// Weighted moments of the samples around a texel centre, for a local linear fit of colour:
// colour(d) = a + B d at offset d from the centre, by weighted least squares; a is the texel's
// colour. One view samples the plane at its pixel pitch, about a texel: the weighted mean of the
// nearest samples is then off by up to half a pitch times the colour gradient, a linear fit is
// not (moving least squares, first order).
struct TexelMoments {
  float w = 0, wx = 0, wy = 0, wxx = 0, wxy = 0, wyy = 0;
  cv::Vec3f c, cx, cy;

  void add(float weight, float dx, float dy, const cv::Vec3f& rgb) {
    w += weight, wx += weight * dx, wy += weight * dy;
    wxx += weight * dx * dx, wxy += weight * dx * dy, wyy += weight * dy * dy;
    c += weight * rgb, cx += weight * dx * rgb, cy += weight * dy * rgb;
  }
  cv::Vec3f value() const {
    // Solve [w wx wy; wx wxx wxy; wy wxy wyy] [a; bx; by] = [c; cx; cy] for a (Cramer's rule);
    // the mean where the samples are too few or in a line to fit a slope.
    const double det = w * (double(wxx) * wyy - double(wxy) * wxy) -
                       wx * (double(wx) * wyy - double(wxy) * wy) +
                       wy * (double(wx) * wxy - double(wxx) * wy);
    const double scale = double(w) * wxx * wyy;
    if (!(det > 0.05 * scale) || w <= 0.0F) return c / w;
    cv::Vec3f a;
    for (int k = 0; k < 3; ++k) {
      const double det_a = c[k] * (double(wxx) * wyy - double(wxy) * wxy) -
                           wx * (double(cx[k]) * wyy - double(wxy) * cy[k]) +
                           wy * (double(cx[k]) * wxy - double(wxx) * cy[k]);
      a[k] = static_cast<float>(std::clamp(det_a / det, 0.0, 255.0));
    }
    return a;
  }
};

// One view's colours over one region's texels.
struct ViewTexels {
  std::int32_t view = -1;
  cv::Vec3f gain{1.0F, 1.0F, 1.0F};
  // Samples within the radius, and (where there are none: between the rows of a grazing view)
  // within twice the radius.
  std::vector<TexelMoments> near;
  std::vector<cv::Vec3f> far_sum;
  std::vector<float> far_weight;
  bool has(int i) const { return near[static_cast<std::size_t>(i)].w > 0.0F; }
  cv::Vec3f at(int i) const { return near[static_cast<std::size_t>(i)].value(); }
  bool hasFar(int i) const { return far_weight[static_cast<std::size_t>(i)] > 0.0F; }
  cv::Vec3f atFar(int i) const {
    return far_sum[static_cast<std::size_t>(i)] / far_weight[static_cast<std::size_t>(i)];
  }
  cv::Vec3d levelled(int i) const {  // with the view's gain
    const cv::Vec3f c = at(i);
    return {c[0], c[1], c[2]};
  }
  cv::Vec3d raw(int i) const {  // as sampled
    const cv::Vec3f c = at(i);
    return {c[0] / gain[0], c[1] / gain[1], c[2] / gain[2]};
  }
};

// The texel grid cut into square regions, and the samples binned into them.
class Regions {
 public:
  Regions(const std::vector<ColourSample>& samples, const TexelGrid& grid, int side,
          double reach_texels)
      : samples_(samples), grid_(grid), side_(side) {
    columns_ = (grid.width + side - 1) / side;
    rows_ = (grid.height + side - 1) / side;
    bins_.resize(count());
    x_.resize(samples.size());
    y_.resize(samples.size());
    for (std::size_t i = 0; i < samples.size(); ++i) {
      const Eigen::Vector2d d = Eigen::Vector2d(samples[i].u, samples[i].v) - grid.origin_uv;
      const double x = d.dot(grid.x_axis) / grid.texel_m, y = d.dot(grid.y_axis) / grid.texel_m;
      x_[i] = static_cast<float>(x);
      y_[i] = static_cast<float>(y);
      if (x < -reach_texels || y < -reach_texels || x > grid.width + reach_texels ||
          y > grid.height + reach_texels) {
        continue;  // reaches no texel
      }
      const int c = std::clamp(static_cast<int>(std::floor(x)) / side, 0, columns_ - 1);
      const int r = std::clamp(static_cast<int>(std::floor(y)) / side, 0, rows_ - 1);
      bins_[static_cast<std::size_t>(r * columns_ + c)].push_back(static_cast<int>(i));
    }
  }

  std::size_t count() const { return static_cast<std::size_t>(columns_) * rows_; }
  // The region (dc, dr) regions away from region b, or -1 past the grid's edge.
  long neighbour(std::size_t b, int dc, int dr) const {
    const int c = static_cast<int>(b % static_cast<std::size_t>(columns_)) + dc;
    const int r = static_cast<int>(b / static_cast<std::size_t>(columns_)) + dr;
    if (c < 0 || r < 0 || c >= columns_ || r >= rows_) return -1;
    return static_cast<long>(r) * columns_ + c;
  }
  int columns() const { return columns_; }
  int rows() const { return rows_; }
  int side() const { return side_; }
  const std::vector<int>& bin(std::size_t region) const { return bins_[region]; }
  const ColourSample& sample(int i) const { return samples_[static_cast<std::size_t>(i)]; }
  float x(int i) const { return x_[static_cast<std::size_t>(i)]; }
  float y(int i) const { return y_[static_cast<std::size_t>(i)]; }
  // Texel (col, row) of a region's local texel index, and whether it lies in the outline.
  cv::Point texel(std::size_t region, int local) const {
    return {static_cast<int>(region % static_cast<std::size_t>(columns_)) * side_ + local % side_,
            static_cast<int>(region / static_cast<std::size_t>(columns_)) * side_ + local / side_};
  }
  bool inside(cv::Point t) const {
    return t.x < grid_.width && t.y < grid_.height && grid_.mask.at<std::uint8_t>(t) != 0;
  }

  // The colours of `views` over the region's texels: every sample of those views within
  // radius of a texel centre, weighted by a Gaussian of its distance.
  void splat(std::size_t region, std::vector<ViewTexels>& views, double radius,
             double sigma) const {
    const auto texels = static_cast<std::size_t>(side_ * side_);
    for (ViewTexels& view : views) {
      view.near.assign(texels, TexelMoments{});
      view.far_sum.assign(texels, cv::Vec3f(0, 0, 0));
      view.far_weight.assign(texels, 0.0F);
    }
    const int rc = static_cast<int>(region % static_cast<std::size_t>(columns_));
    const int rr = static_cast<int>(region / static_cast<std::size_t>(columns_));
    const int x0 = rc * side_, y0 = rr * side_;
    const auto radius2 = static_cast<float>(radius * radius);
    const auto inverse_two_sigma2 = static_cast<float>(1.0 / (2.0 * sigma * sigma));
    const double far = 2.0 * radius;
    const auto far2 = static_cast<float>(far * far);
    const float inverse_two_far_sigma2 = inverse_two_sigma2 / 4.0F;
    for (int dr = -1; dr <= 1; ++dr) {
      for (int dc = -1; dc <= 1; ++dc) {
        if (rc + dc < 0 || rr + dr < 0 || rc + dc >= columns_ || rr + dr >= rows_) continue;
        for (const int i : bins_[static_cast<std::size_t>((rr + dr) * columns_ + rc + dc)]) {
          const ColourSample& s = samples_[static_cast<std::size_t>(i)];
          const auto view = std::find_if(views.begin(), views.end(),
                                         [&](const ViewTexels& v) { return v.view == s.view; });
          if (view == views.end()) continue;
          const float x = x_[static_cast<std::size_t>(i)], y = y_[static_cast<std::size_t>(i)];
          const int c_lo = std::max(x0, static_cast<int>(std::floor(x - far)));
          const int c_hi = std::min(x0 + side_ - 1, static_cast<int>(std::floor(x + far)));
          const int r_lo = std::max(y0, static_cast<int>(std::floor(y - far)));
          const int r_hi = std::min(y0 + side_ - 1, static_cast<int>(std::floor(y + far)));
          const cv::Vec3f rgb(s.rgb[0] * view->gain[0], s.rgb[1] * view->gain[1],
                              s.rgb[2] * view->gain[2]);
          for (int r = r_lo; r <= r_hi; ++r) {
            for (int c = c_lo; c <= c_hi; ++c) {
              const float dx = static_cast<float>(c) + 0.5F - x;
              const float dy = static_cast<float>(r) + 0.5F - y;
              const float d2 = dx * dx + dy * dy;
              const auto local = static_cast<std::size_t>((r - y0) * side_ + c - x0);
              if (d2 <= radius2) {
                const float w = std::exp(-d2 * inverse_two_sigma2);
                view->near[local].add(w, -dx, -dy, rgb);
              } else if (d2 <= far2) {
                const float w = std::exp(-d2 * inverse_two_far_sigma2);
                view->far_sum[local] += w * rgb;
                view->far_weight[local] += w;
              }
            }
          }
        }
      }
    }
  }

 private:
  const std::vector<ColourSample>& samples_;
  const TexelGrid& grid_;
  int side_;
  int columns_ = 0, rows_ = 0;
  std::vector<std::vector<int>> bins_;
  std::vector<float> x_, y_;  // each sample's position in texels
};

// Each region's candidates: the views of most summed sample weight in it.
std::vector<RegionViews> candidatesOf(const Regions& regions, int per_region) {
  std::vector<RegionViews> candidates(regions.count());
  std::vector<std::pair<double, std::int32_t>> totals;
  for (std::size_t b = 0; b < regions.count(); ++b) {
    totals.clear();
    for (const int i : regions.bin(b)) {
      const ColourSample& s = regions.sample(i);
      auto it = std::find_if(totals.begin(), totals.end(),
                             [&](const auto& t) { return t.second == s.view; });
      if (it == totals.end()) it = totals.insert(totals.end(), {0.0, s.view});
      it->first += std::exp(static_cast<double>(s.score));
    }
    std::sort(totals.begin(), totals.end(), std::greater<>());
    if (totals.size() > static_cast<std::size_t>(per_region)) totals.resize(per_region);
    for (const auto& [weight, view] : totals) {
      candidates[b].views.push_back(view);
      candidates[b].weights.push_back(weight);
    }
  }
  return candidates;
}

// Log gains of every view, from the texels two candidates of a region share (nearest texel).
std::unordered_map<std::int32_t, cv::Vec3f> viewGains(const Regions& regions,
                                                      const std::vector<RegionViews>& candidates) {
  std::unordered_map<std::int32_t, int> index;
  std::vector<std::int32_t> ids;
  std::map<std::pair<int, int>, ViewPair> pairs;
  const int side = regions.side();
  std::vector<std::vector<cv::Vec4f>> texels;  // per candidate: colour sum, count
  for (std::size_t b = 0; b < regions.count(); ++b) {
    const RegionViews& region = candidates[b];
    if (region.views.size() < 2) continue;
    texels.assign(region.views.size(),
                  std::vector<cv::Vec4f>(static_cast<std::size_t>(side * side), cv::Vec4f()));
    const cv::Point corner = regions.texel(b, 0);
    for (const int i : regions.bin(b)) {
      const ColourSample& s = regions.sample(i);
      const auto k = std::find(region.views.begin(), region.views.end(), s.view);
      const int c = static_cast<int>(std::floor(regions.x(i))) - corner.x;
      const int r = static_cast<int>(std::floor(regions.y(i))) - corner.y;
      if (k == region.views.end() || c < 0 || r < 0 || c >= side || r >= side) continue;
      texels[static_cast<std::size_t>(k - region.views.begin())]
            [static_cast<std::size_t>(r * side + c)] += cv::Vec4f(s.rgb[0], s.rgb[1], s.rgb[2], 1);
    }
    for (std::size_t a = 0; a < region.views.size(); ++a) {
      for (std::size_t o = a + 1; o < region.views.size(); ++o) {
        int ia = index.try_emplace(region.views[a], static_cast<int>(ids.size())).first->second;
        if (ia == static_cast<int>(ids.size())) ids.push_back(region.views[a]);
        int io = index.try_emplace(region.views[o], static_cast<int>(ids.size())).first->second;
        if (io == static_cast<int>(ids.size())) ids.push_back(region.views[o]);
        bool swapped = ia > io;
        if (swapped) std::swap(ia, io);
        ViewPair& pair = pairs.try_emplace({ia, io}, ViewPair{ia, io, 0.0, {}}).first->second;
        for (std::size_t t = 0; t < texels[a].size(); ++t) {
          const cv::Vec4f& ca = texels[a][t];
          const cv::Vec4f& co = texels[o][t];
          if (ca[3] == 0.0F || co[3] == 0.0F) continue;
          for (int c = 0; c < 3; ++c) {
            const double ratio = std::log((ca[c] / ca[3] + 1.0) / (co[c] / co[3] + 1.0));
            pair.log_ratio[c] += swapped ? -ratio : ratio;
          }
          pair.shared += 1.0;
        }
      }
    }
  }
  std::vector<ViewPair> list;
  for (auto& [key, pair] : pairs) {
    if (pair.shared < 1.0) continue;
    pair.log_ratio /= pair.shared;
    list.push_back(pair);
  }
  const std::vector<cv::Vec3d> log_gains = viewLogGains(static_cast<int>(ids.size()), list);
  std::unordered_map<std::int32_t, cv::Vec3f> gains;
  for (std::size_t v = 0; v < ids.size(); ++v) {
    cv::Vec3f gain;
    for (int c = 0; c < 3; ++c) {
      // g_v is how much brighter view v is than the consensus: its colours are divided by e^g.
      gain[c] =
          static_cast<float>(std::exp(-std::clamp(log_gains[v][c], -kMaxLogGain, kMaxLogGain)));
    }
    gains[ids[v]] = gain;
  }
  return gains;
}

// Per-region colour offsets that close the measured steps at seams and vary smoothly elsewhere:
// least squares over (o_a - o_b - step_ab)^2 at seams, (o_a - o_b)^2 between regions of the
// same view, and a small prior mu o^2.
struct Seam {
  std::size_t low = 0, high = 0;  // region indices, low < high
  cv::Vec3d step;                 // summed colour of high's view minus low's, over `texels`
  double texels = 0.0;
};

std::vector<cv::Vec3d> regionOffsets(std::size_t count, const std::vector<int>& view_of,
                                     int columns, const std::vector<Seam>& seams) {
  constexpr double kSameView = 1.0, kPrior = 0.02;
  std::vector<Eigen::Triplet<double>> entries;
  Eigen::MatrixXd rhs = Eigen::MatrixXd::Zero(static_cast<Eigen::Index>(count), 3);
  const auto couple = [&](std::size_t a, std::size_t b, double w) {
    const auto ia = static_cast<int>(a), ib = static_cast<int>(b);
    entries.emplace_back(ia, ia, w);
    entries.emplace_back(ib, ib, w);
    entries.emplace_back(ia, ib, -w);
    entries.emplace_back(ib, ia, -w);
  };
  for (const Seam& seam : seams) {
    if (seam.texels <= 0.0) continue;
    couple(seam.low, seam.high, 1.0);
    for (int c = 0; c < 3; ++c) {
      const double step = seam.step[c] / seam.texels;
      rhs(static_cast<Eigen::Index>(seam.low), c) += step;
      rhs(static_cast<Eigen::Index>(seam.high), c) -= step;
    }
  }
  for (std::size_t b = 0; b < count; ++b) {
    entries.emplace_back(static_cast<int>(b), static_cast<int>(b), kPrior);
    if (view_of[b] < 0) continue;
    const std::size_t right = b + 1, below = b + static_cast<std::size_t>(columns);
    if ((b + 1) % static_cast<std::size_t>(columns) != 0 && view_of[right] == view_of[b]) {
      couple(b, right, kSameView);
    }
    if (below < count && view_of[below] == view_of[b]) couple(b, below, kSameView);
  }
  Eigen::SparseMatrix<double> normal(static_cast<Eigen::Index>(count),
                                     static_cast<Eigen::Index>(count));
  normal.setFromTriplets(entries.begin(), entries.end());
  std::vector<cv::Vec3d> offsets(count, cv::Vec3d(0, 0, 0));
  const Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> solver(normal);
  if (solver.info() != Eigen::Success) return offsets;
  const Eigen::MatrixXd solution = solver.solve(rhs);
  for (std::size_t b = 0; b < count; ++b) {
    for (int c = 0; c < 3; ++c) {
      offsets[b][c] =
          std::clamp(solution(static_cast<Eigen::Index>(b), c), -kMaxOffset, kMaxOffset);
    }
  }
  return offsets;
}

}  // namespace

ViewComposite composeByViews(const std::vector<ColourSample>& samples, const TexelGrid& grid,
                             const ViewSelectionConfig& config, double radius_texels,
                             double sigma_texels) {
  ViewComposite out;
  out.image = cv::Mat::zeros(grid.height, grid.width, CV_8UC3);
  out.observed = cv::Mat::zeros(grid.height, grid.width, CV_8UC1);
  if (samples.empty() || grid.width == 0 || grid.height == 0) return out;
  const int side = config.region_texels;
  const Regions regions(samples, grid, side, 2.0 * radius_texels);
  const std::vector<RegionViews> candidates = candidatesOf(regions, config.views_per_region);
  const std::vector<int> labels =
      labelRegions(candidates, regions.columns(), regions.rows(), config.smoothness);
  const std::size_t count = regions.count();
  std::vector<int> view_of(count, -1);  // the chosen view's id per region
  std::vector<std::int32_t> used;
  for (std::size_t b = 0; b < count; ++b) {
    if (labels[b] < 0) continue;
    view_of[b] = candidates[b].views[static_cast<std::size_t>(labels[b])];
    used.push_back(view_of[b]);
    ++out.regions;
  }
  for (std::size_t b = 0; b < count; ++b) {
    const std::size_t right = b + 1, below = b + static_cast<std::size_t>(regions.columns());
    const bool has_right = (b + 1) % static_cast<std::size_t>(regions.columns()) != 0;
    if (view_of[b] < 0) continue;
    if (has_right && view_of[right] >= 0 && view_of[right] != view_of[b]) ++out.seams;
    if (below < count && view_of[below] >= 0 && view_of[below] != view_of[b]) ++out.seams;
  }
  std::sort(used.begin(), used.end());
  out.views_used = static_cast<int>(std::unique(used.begin(), used.end()) - used.begin());
  const std::unordered_map<std::int32_t, cv::Vec3f> gains =
      config.level_seams ? viewGains(regions, candidates)
                         : std::unordered_map<std::int32_t, cv::Vec3f>{};

  // The views a region's texels need: its own, its 8 neighbours' (blended near seams), then its
  // other candidates (for texels its own view did not see).
  const auto neededViews = [&](std::size_t b, std::vector<ViewTexels>& views) {
    views.clear();
    const auto add = [&](std::int32_t view) {
      if (std::none_of(views.begin(), views.end(),
                       [&](const ViewTexels& v) { return v.view == view; })) {
        ViewTexels texels;
        texels.view = view;
        if (const auto it = gains.find(view); it != gains.end()) texels.gain = it->second;
        views.push_back(std::move(texels));
      }
    };
    add(view_of[b]);
    for (int dr = -1; dr <= 1; ++dr) {
      for (int dc = -1; dc <= 1; ++dc) {
        const long n = regions.neighbour(b, dc, dr);
        if (n >= 0 && view_of[static_cast<std::size_t>(n)] >= 0) {
          add(view_of[static_cast<std::size_t>(n)]);
        }
      }
    }
    for (const std::int32_t view : candidates[b].views) add(view);
  };
  const auto find = [](const std::vector<ViewTexels>& views, std::int32_t view) {
    return &*std::find_if(views.begin(), views.end(),
                          [&](const ViewTexels& v) { return v.view == view; });
  };
  const double seam_width = std::max(config.seam_texels, 1);
  // Distance (texels) from a texel centre at local (lx, ly) to the neighbouring region in
  // direction (dc, dr).
  const auto distanceTo = [&](double lx, double ly, int dc, int dr) {
    const double dx = dc < 0 ? lx : dc > 0 ? side - lx : 0.0;
    const double dy = dr < 0 ? ly : dr > 0 ? side - ly : 0.0;
    return std::hypot(dx, dy);
  };

  // Sweep one: the colour steps between the two views at each seam, over the texels within
  // seam_width of it on either side that both views saw.
  std::map<std::pair<std::size_t, std::size_t>, Seam> seams;
  std::vector<ViewTexels> views;
  const int texels = side * side;
  for (std::size_t b = 0; b < count && config.level_seams; ++b) {
    if (view_of[b] < 0) continue;
    neededViews(b, views);
    regions.splat(b, views, radius_texels, sigma_texels);
    const ViewTexels* own = find(views, view_of[b]);
    for (const auto& [dc, dr] : {std::pair{1, 0}, {-1, 0}, {0, 1}, {0, -1}}) {
      const long neighbour = regions.neighbour(b, dc, dr);
      if (neighbour < 0) continue;
      const auto n = static_cast<std::size_t>(neighbour);
      if (view_of[n] < 0 || view_of[n] == view_of[b]) continue;
      const ViewTexels* other = find(views, view_of[n]);
      Seam& seam = seams.try_emplace({std::min(b, n), std::max(b, n)}).first->second;
      seam.low = std::min(b, n);
      seam.high = std::max(b, n);
      const double sign = n > b ? 1.0 : -1.0;  // step: high's view minus low's
      for (int i = 0; i < texels; ++i) {
        const double lx = i % side + 0.5, ly = i / side + 0.5;
        if (distanceTo(lx, ly, dc, dr) > seam_width || !own->has(i) || !other->has(i) ||
            !regions.inside(regions.texel(b, i))) {
          continue;
        }
        const cv::Vec3f step = other->at(i) - own->at(i);
        seam.step += sign * cv::Vec3d(step[0], step[1], step[2]);
        seam.texels += 1.0;
      }
    }
  }
  std::vector<Seam> seam_list;
  for (const auto& [key, seam] : seams) seam_list.push_back(seam);
  const std::vector<cv::Vec3d> offsets =
      config.level_seams ? regionOffsets(count, view_of, regions.columns(), seam_list)
                         : std::vector<cv::Vec3d>(count, cv::Vec3d(0, 0, 0));

  // The offset of `view` at a texel of region b: interpolated over the regions around b that
  // took that view (a tent of one region's side around each centre); b's own where none did.
  const auto offsetOf = [&](std::size_t b, std::int32_t view, double tx, double ty) {
    const auto rc = static_cast<double>(b % static_cast<std::size_t>(regions.columns()));
    const auto rr = static_cast<double>(b / static_cast<std::size_t>(regions.columns()));
    cv::Vec3d sum(0, 0, 0);
    double total = 0.0;
    for (int dr = -1; dr <= 1; ++dr) {
      for (int dc = -1; dc <= 1; ++dc) {
        const long neighbour = regions.neighbour(b, dc, dr);
        if (neighbour < 0 || view_of[static_cast<std::size_t>(neighbour)] != view) continue;
        const auto m = static_cast<std::size_t>(neighbour);
        const double cx = (rc + dc + 0.5) * side, cy = (rr + dr + 0.5) * side;
        const double w = std::max(0.02, 1.0 - std::abs(tx - cx) / side) *
                         std::max(0.02, 1.0 - std::abs(ty - cy) / side);
        sum += w * offsets[m];
        total += w;
      }
    }
    return total > 0.0 ? cv::Vec3d(sum / total) : offsets[b];
  };

  // Sweep two: the composite. A texel blends its region's view (weight 1) with each different
  // view of a neighbouring region within seam_width (weight falling linearly to 0 there).
  double raw_step = 0.0, levelled_step = 0.0, seam_texels = 0.0;
  const auto meanAbs = [](const cv::Vec3d& step) {
    return (std::abs(step[0]) + std::abs(step[1]) + std::abs(step[2])) / 3.0;
  };
  std::vector<std::pair<std::int32_t, double>> blend;
  for (std::size_t b = 0; b < count; ++b) {
    if (view_of[b] < 0) continue;
    neededViews(b, views);
    regions.splat(b, views, radius_texels, sigma_texels);
    for (int i = 0; i < texels; ++i) {
      const cv::Point t = regions.texel(b, i);
      if (!regions.inside(t)) continue;
      const double lx = i % side + 0.5, ly = i / side + 0.5;
      blend.assign(1, {view_of[b], 1.0});
      for (int dr = -1; dr <= 1; ++dr) {
        for (int dc = -1; dc <= 1; ++dc) {
          const long neighbour = regions.neighbour(b, dc, dr);
          if ((dc == 0 && dr == 0) || neighbour < 0) continue;
          const int n = view_of[static_cast<std::size_t>(neighbour)];
          const double w = 1.0 - distanceTo(lx, ly, dc, dr) / seam_width;
          if (n < 0 || w <= 0.0) continue;
          auto it =
              std::find_if(blend.begin(), blend.end(), [&](const auto& e) { return e.first == n; });
          if (it == blend.end())
            blend.emplace_back(n, w);
          else
            it->second = std::max(it->second, w);
        }
      }
      const double tx = t.x + 0.5, ty = t.y + 0.5;
      cv::Vec3d colour(0, 0, 0);
      double total = 0.0;
      for (const auto& [view, w] : blend) {
        const ViewTexels* v = find(views, view);
        if (!v->has(i)) continue;
        const cv::Vec3f c = v->at(i);
        colour += w * (cv::Vec3d(c[0], c[1], c[2]) + offsetOf(b, view, tx, ty));
        total += w;
      }
      if (const ViewTexels* own = find(views, blend[0].first); blend.size() > 1 && own->has(i)) {
        // The step between this region's view and each other one it blends with here, as
        // sampled (gain undone) and as levelled.
        const cv::Vec3d own_raw = own->raw(i);
        const cv::Vec3d own_levelled = own->levelled(i) + offsetOf(b, own->view, tx, ty);
        for (std::size_t k = 1; k < blend.size(); ++k) {
          const ViewTexels* v = find(views, blend[k].first);
          if (!v->has(i)) continue;
          raw_step += meanAbs(v->raw(i) - own_raw);
          levelled_step += meanAbs(v->levelled(i) + offsetOf(b, v->view, tx, ty) - own_levelled);
          seam_texels += 1.0;
        }
      }
      if (total <= 0.0) {
        // Not seen by the views blended here: the region's heaviest candidate that saw it;
        // failing that, the nearest samples a little further off (between the rows of a grazing
        // view). A view occluded here has none of either nearby.
        for (const bool far : {false, true}) {
          for (const std::int32_t view : candidates[b].views) {
            const ViewTexels* v = find(views, view);
            if (far ? !v->hasFar(i) : !v->has(i)) continue;
            const cv::Vec3f c = far ? v->atFar(i) : v->at(i);
            colour = cv::Vec3d(c[0], c[1], c[2]) + offsets[b];
            total = 1.0;
            break;
          }
          if (total > 0.0) break;
        }
      }
      if (total <= 0.0) continue;
      colour /= total;
      out.image.at<cv::Vec3b>(t) = cv::Vec3b(cv::saturate_cast<std::uint8_t>(colour[0]),
                                             cv::saturate_cast<std::uint8_t>(colour[1]),
                                             cv::saturate_cast<std::uint8_t>(colour[2]));
      out.observed.at<std::uint8_t>(t) = 255;
    }
  }
  if (seam_texels > 0.0) {
    out.seam_step = raw_step / seam_texels;
    out.seam_step_levelled = levelled_step / seam_texels;
  }
  return out;
}

}  // namespace tessera::texture
