// alignViews: each view's in-plane shift against the consensus of all views
// (include/tessera/texture/view_selection.h).
#include <algorithm>
#include <cmath>
#include <unordered_map>

#include <opencv2/imgproc.hpp>

#include "tessera/texture/view_selection.h"

namespace tessera::texture {

namespace {

using planes::ColourSample;

constexpr int kRounds = 2;
constexpr std::size_t kMaxProbes = 6000;  // samples of a view that score a shift
constexpr double kMinCorrelation = 0.2;   // below it a view has nothing to align with
// A shift must beat staying put by this much correlation per texel moved: on a periodic
// texture a shift by one period correlates as well as none.
constexpr double kShiftCost = 0.01;

double grey(const ColourSample& s) {
  return 0.299 * s.rgb[0] + 0.587 * s.rgb[1] + 0.114 * s.rgb[2];
}

// The mean grey of all samples on the texel grid (bilinear splats), and where it is defined.
struct Consensus {
  cv::Mat grey;    // CV_32F
  cv::Mat weight;  // CV_32F

  float at(double x, double y, bool& valid) const {
    // Bilinear, texel centres at (c + 0.5, r + 0.5).
    const double fx = x - 0.5, fy = y - 0.5;
    const int c = static_cast<int>(std::floor(fx)), r = static_cast<int>(std::floor(fy));
    if (c < 0 || r < 0 || c + 1 >= grey.cols || r + 1 >= grey.rows) return valid = false, 0.0F;
    const auto ax = static_cast<float>(fx - c), ay = static_cast<float>(fy - r);
    const float w00 = weight.at<float>(r, c), w01 = weight.at<float>(r, c + 1);
    const float w10 = weight.at<float>(r + 1, c), w11 = weight.at<float>(r + 1, c + 1);
    if (w00 <= 0.0F || w01 <= 0.0F || w10 <= 0.0F || w11 <= 0.0F) return valid = false, 0.0F;
    valid = true;
    return (1 - ay) * ((1 - ax) * grey.at<float>(r, c) + ax * grey.at<float>(r, c + 1)) +
           ay * ((1 - ax) * grey.at<float>(r + 1, c) + ax * grey.at<float>(r + 1, c + 1));
  }
};

Consensus consensusOf(const std::vector<double>& x, const std::vector<double>& y,
                      const std::vector<double>& g, const TexelGrid& grid) {
  Consensus out{cv::Mat::zeros(grid.height, grid.width, CV_32F),
                cv::Mat::zeros(grid.height, grid.width, CV_32F)};
  for (std::size_t i = 0; i < x.size(); ++i) {
    const double fx = x[i] - 0.5, fy = y[i] - 0.5;
    const int c = static_cast<int>(std::floor(fx)), r = static_cast<int>(std::floor(fy));
    const double ax = fx - c, ay = fy - r;
    for (const auto& [dc, dr, w] : {std::tuple{0, 0, (1 - ax) * (1 - ay)},
                                    {1, 0, ax * (1 - ay)},
                                    {0, 1, (1 - ax) * ay},
                                    {1, 1, ax * ay}}) {
      if (c + dc < 0 || r + dr < 0 || c + dc >= grid.width || r + dr >= grid.height) continue;
      out.grey.at<float>(r + dr, c + dc) += static_cast<float>(w * g[i]);
      out.weight.at<float>(r + dr, c + dc) += static_cast<float>(w);
    }
  }
  // Fill the texels between samples from their neighbours (a sample lands in about every texel
  // where views are dense, and not at all between the rows of a grazing view).
  cv::Mat blurred_grey, blurred_weight;
  cv::GaussianBlur(out.grey, blurred_grey, cv::Size(5, 5), 1.0);
  cv::GaussianBlur(out.weight, blurred_weight, cv::Size(5, 5), 1.0);
  out.grey = blurred_grey / cv::max(blurred_weight, 1e-6);
  out.weight = blurred_weight;
  return out;
}

// Normalised cross-correlation of a view's probe samples with the consensus at shift (dx, dy).
double correlation(const std::vector<std::size_t>& probes, const std::vector<double>& x,
                   const std::vector<double>& y, const std::vector<double>& g,
                   const Consensus& consensus, double dx, double dy) {
  double n = 0, sa = 0, sb = 0, saa = 0, sbb = 0, sab = 0;
  for (const std::size_t i : probes) {
    bool valid = false;
    const double b = consensus.at(x[i] + dx, y[i] + dy, valid);
    if (!valid) continue;
    const double a = g[i];
    n += 1, sa += a, sb += b, saa += a * a, sbb += b * b, sab += a * b;
  }
  if (n < 50) return -1.0;
  const double va = saa - sa * sa / n, vb = sbb - sb * sb / n;
  if (va <= 1e-9 || vb <= 1e-9) return -1.0;
  return (sab - sa * sb / n) / std::sqrt(va * vb);
}

}  // namespace

std::vector<ViewShift> alignViews(std::vector<ColourSample>& samples, const TexelGrid& grid,
                                  const ViewAlignmentConfig& config) {
  std::vector<ViewShift> shifts;
  if (!config.enabled || samples.empty() || grid.width < 4 || grid.height < 4) return shifts;
  const std::size_t count = samples.size();
  std::vector<double> x(count), y(count), g(count);
  std::unordered_map<std::int32_t, std::vector<std::size_t>> by_view;
  for (std::size_t i = 0; i < count; ++i) {
    const Eigen::Vector2d d = Eigen::Vector2d(samples[i].u, samples[i].v) - grid.origin_uv;
    x[i] = d.dot(grid.x_axis) / grid.texel_m;
    y[i] = d.dot(grid.y_axis) / grid.texel_m;
    g[i] = grey(samples[i]);
    if (samples[i].view >= 0) by_view[samples[i].view].push_back(i);
  }
  // Views in id order, so that the result does not depend on hash order.
  std::vector<std::int32_t> views;
  for (const auto& [view, members] : by_view) {
    if (members.size() >= static_cast<std::size_t>(config.min_samples)) views.push_back(view);
  }
  std::sort(views.begin(), views.end());
  if (views.size() < 2) return shifts;
  std::unordered_map<std::int32_t, ViewShift> total;
  for (int round = 0; round < kRounds; ++round) {
    const Consensus consensus = consensusOf(x, y, g, grid);
    for (const std::int32_t view : views) {
      const std::vector<std::size_t>& members = by_view[view];
      std::vector<std::size_t> probes;
      const std::size_t stride = std::max<std::size_t>(1, members.size() / kMaxProbes);
      for (std::size_t k = 0; k < members.size(); k += stride) probes.push_back(members[k]);
      const auto score = [&](double dx, double dy) {
        return correlation(probes, x, y, g, consensus, dx, dy) - kShiftCost * std::hypot(dx, dy);
      };
      double best_dx = 0.0, best_dy = 0.0, best = score(0.0, 0.0);
      const double still = best;
      // Coarse: every 2 texels within the range; then finer steps around the best.
      const double range = config.max_shift_texels;
      for (double dy = -range; dy <= range; dy += 2.0) {
        for (double dx = -range; dx <= range; dx += 2.0) {
          if (const double s = score(dx, dy); s > best) best = s, best_dx = dx, best_dy = dy;
        }
      }
      for (const double step : {1.0, 0.5, 0.25}) {
        const double cx = best_dx, cy = best_dy;
        for (int j = -1; j <= 1; ++j) {
          for (int i = -1; i <= 1; ++i) {
            const double dx = cx + i * step, dy = cy + j * step;
            if (std::hypot(dx, dy) > range * std::sqrt(2.0)) continue;
            if (const double s = score(dx, dy); s > best) best = s, best_dx = dx, best_dy = dy;
          }
        }
      }
      if (best + kShiftCost * std::hypot(best_dx, best_dy) < kMinCorrelation || best <= still) {
        continue;
      }
      for (const std::size_t i : members) x[i] += best_dx, y[i] += best_dy;
      ViewShift& shift = total[view];
      shift.view = view;
      shift.dx += best_dx;
      shift.dy += best_dy;
    }
  }
  for (const std::int32_t view : views) {
    const auto it = total.find(view);
    if (it == total.end() || (it->second.dx == 0.0 && it->second.dy == 0.0)) continue;
    shifts.push_back(it->second);
    const Eigen::Vector2d move =
        grid.texel_m * (it->second.dx * grid.x_axis + it->second.dy * grid.y_axis);
    for (const std::size_t i : by_view[view]) {
      samples[i].u += static_cast<float>(move.x());
      samples[i].v += static_cast<float>(move.y());
    }
  }
  return shifts;
}

}  // namespace tessera::texture
