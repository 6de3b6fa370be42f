#include "tessera/match/pattern_alignment.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <vector>

#include <Eigen/LU>

namespace tessera::match {

namespace {

// The shortest basis of the same lattice (Lagrange-Gauss reduction).
core::Lattice2 reduced(core::Lattice2 l) {
  for (int i = 0; i < 64; ++i) {
    if (l.v2.squaredNorm() < l.v1.squaredNorm()) std::swap(l.v1, l.v2);
    const double k = std::round(l.v1.dot(l.v2) / l.v1.squaredNorm());
    if (k == 0.0) break;
    l.v2 -= k * l.v1;
  }
  return l;
}

// The similarity nearest to the linear map A, and A's relative distance from it.
core::Similarity2 nearestSimilarity(const Eigen::Matrix2d& A, double& error) {
  const double a = 0.5 * (A(0, 0) + A(1, 1)), b = 0.5 * (A(1, 0) - A(0, 1));
  Eigen::Matrix2d S;
  S << a, -b, b, a;
  error = (A - S).norm() / std::max(S.norm(), 1e-12);
  return {a, b, 0.0, 0.0};
}

// A whole number of texels n wrapped into [0, size).
int wrapTexel(double n, int size) {
  const auto i = static_cast<int>(static_cast<long long>(n) % size);
  return i < 0 ? i + size : i;
}

// Bilinear colour of a tile that repeats along both axes, at tile pixel (x, y). The cost
// function calls it for every sample at every phase tried: the four neighbours are wrapped
// with one integer division per axis.
Eigen::Vector3f sampleWrapped(const cv::Mat& tile, double x, double y) {
  const double fx = std::floor(x), fy = std::floor(y);
  const float ax = static_cast<float>(x - fx), ay = static_cast<float>(y - fy);
  const int i0 = wrapTexel(fx, tile.cols), j0 = wrapTexel(fy, tile.rows);
  const int i1 = i0 + 1 == tile.cols ? 0 : i0 + 1, j1 = j0 + 1 == tile.rows ? 0 : j0 + 1;
  const auto at = [&](int i, int j) {
    const cv::Vec3b& c = tile.at<cv::Vec3b>(j, i);
    return Eigen::Vector3f(c[0], c[1], c[2]);
  };
  return (1 - ay) * ((1 - ax) * at(i0, j0) + ax * at(i1, j0)) +
         ay * ((1 - ax) * at(i0, j1) + ax * at(i1, j1));
}

// Points of the new pattern (texel coordinates) with their colours: tile pixel (i, j) is the
// point (i / W) v1 + (j / H) v2.
struct Sample {
  Eigen::Vector2d point;
  Eigen::Vector3f rgb;
};

std::vector<Sample> tileSamples(const cv::Mat& tile_rgb, const cv::Mat& tile_mask,
                                const core::Lattice2& lattice) {
  std::vector<Sample> samples;
  for (int j = 0; j < tile_rgb.rows; ++j) {
    for (int i = 0; i < tile_rgb.cols; ++i) {
      if (!tile_mask.empty() && tile_mask.at<std::uint8_t>(j, i) == 0) continue;
      const cv::Vec3b& c = tile_rgb.at<cv::Vec3b>(j, i);
      samples.push_back(
          {(i + 0.5) / tile_rgb.cols * lattice.v1 + (j + 0.5) / tile_rgb.rows * lattice.v2,
           Eigen::Vector3f(c[0], c[1], c[2])});
    }
  }
  return samples;
}

}  // namespace

std::optional<core::Similarity2> alignPattern(const cv::Mat& tile_rgb, const cv::Mat& tile_mask,
                                              const core::Lattice2& lattice,
                                              const StoredTexture& stored,
                                              const PatternAlignmentConfig& config) {
  if (!stored.pattern || stored.tile_rgb.empty() || tile_rgb.empty() ||
      !(lattice.cellArea() > 1e-9) || !(stored.lattice.cellArea() > 1e-9)) {
    return std::nullopt;
  }
  const core::Lattice2 mine = reduced(lattice), theirs = reduced(stored.lattice);
  // The pairings of the two reduced bases, up to sign and order: A mine = theirs-pairing.
  std::optional<core::Similarity2> linear;
  double best_error = config.max_shape_error;
  const Eigen::Matrix2d mine_inverse = mine.basis().inverse();
  for (const bool swap : {false, true}) {
    for (const double s1 : {1.0, -1.0}) {
      for (const double s2 : {1.0, -1.0}) {
        Eigen::Matrix2d target;
        target << s1 * (swap ? theirs.v2 : theirs.v1), s2 * (swap ? theirs.v1 : theirs.v2);
        double error = 0.0;
        const core::Similarity2 S = nearestSimilarity(target * mine_inverse, error);
        if (error < best_error && S.scale() >= config.min_scale && S.scale() <= config.max_scale) {
          best_error = error;
          linear = S;
        }
      }
    }
  }
  if (!linear) return std::nullopt;

  // The phase: the translation t within one stored cell minimising the colour difference
  // between the new tile's points and the stored tile at S p + t. A grid of about one texel,
  // then half and quarter steps around the best. The grid costs (cell area)^2, so a large
  // cell (a floor's tiles, hundreds of texels a side) is searched on a coarser grid with a
  // subset of the points first, and its best few phases refined with every point.
  const std::vector<Sample> samples = tileSamples(tile_rgb, tile_mask, lattice);
  if (samples.empty()) return std::nullopt;
  constexpr double kMaxPhases = 4096.0, kMaxCoarseSamples = 2048.0;
  const Eigen::Matrix2d to_lattice = stored.lattice.basis().inverse();
  const cv::Mat& tile = stored.tile_rgb;
  std::vector<Eigen::Vector2d> mapped(samples.size());
  for (std::size_t k = 0; k < samples.size(); ++k) mapped[k] = linear->apply(samples[k].point);
  const auto cost = [&](const Eigen::Vector2d& t, std::size_t stride) {
    double sum = 0.0;
    for (std::size_t k = 0; k < samples.size(); k += stride) {
      const Eigen::Vector2d c = to_lattice * (mapped[k] + t);
      sum += (sampleWrapped(tile, c.x() * tile.cols, c.y() * tile.rows) - samples[k].rgb)
                 .squaredNorm();
    }
    return sum;
  };
  const double cell_n1 = std::max(1.0, std::ceil(stored.lattice.v1.norm()));
  const double cell_n2 = std::max(1.0, std::ceil(stored.lattice.cellArea() / cell_n1));
  const double coarse = std::max(1.0, std::sqrt(cell_n1 * cell_n2 / kMaxPhases));  // texels
  const int n1 = std::max(1, static_cast<int>(std::ceil(cell_n1 / coarse)));
  const int n2 = std::max(1, static_cast<int>(std::ceil(cell_n2 / coarse)));
  const auto stride = static_cast<std::size_t>(
      std::max(1.0, std::ceil(static_cast<double>(samples.size()) / kMaxCoarseSamples)));
  std::vector<std::pair<double, Eigen::Vector2d>> phases;  // (cost, t)
  for (int a = 0; a < n1; ++a) {
    for (int b = 0; b < n2; ++b) {
      const Eigen::Vector2d t = (static_cast<double>(a) / n1) * stored.lattice.v1 +
                                (static_cast<double>(b) / n2) * stored.lattice.v2;
      phases.emplace_back(cost(t, stride), t);
    }
  }
  const std::size_t keep = std::min<std::size_t>(coarse > 1.0 || stride > 1 ? 4 : 1, phases.size());
  std::partial_sort(phases.begin(), phases.begin() + static_cast<std::ptrdiff_t>(keep),
                    phases.end(), [](const auto& x, const auto& y) { return x.first < y.first; });
  Eigen::Vector2d best_t = phases.front().second;
  double best_cost = std::numeric_limits<double>::infinity();
  for (std::size_t p = 0; p < keep; ++p) {
    Eigen::Vector2d t_p = phases[p].second;
    double cost_p = cost(t_p, 1);
    for (double step = 0.5 * coarse; step >= 0.25; step *= 0.5) {
      const Eigen::Vector2d centre = t_p;
      for (int dy = -1; dy <= 1; ++dy) {
        for (int dx = -1; dx <= 1; ++dx) {
          const Eigen::Vector2d t = centre + step * Eigen::Vector2d(dx, dy);
          const double c = cost(t, 1);
          if (c < cost_p) cost_p = c, t_p = t;
        }
      }
    }
    if (cost_p < best_cost) best_cost = cost_p, best_t = t_p;
  }
  return core::Similarity2{linear->a, linear->b, best_t.x(), best_t.y()};
}

core::Similarity2 refineAlignment(const cv::Mat& rgb, const cv::Mat& mask,
                                  const StoredTexture& stored, const core::Similarity2& initial) {
  if (!stored.pattern || stored.tile_rgb.empty()) return initial;
  // Texels between samples: every 4th each way, and at most about 40,000 samples, so that a
  // large bitmap (a floor tile) costs no more than a wall.
  constexpr double kMaxSamples = 40000.0;
  const int stride = std::max(
      4, static_cast<int>(std::ceil(std::sqrt(static_cast<double>(rgb.total()) / kMaxSamples))));
  std::vector<Sample> samples;
  for (int row = stride / 2; row < rgb.rows; row += stride) {
    for (int col = stride / 2; col < rgb.cols; col += stride) {
      if (!mask.empty() && mask.at<std::uint8_t>(row, col) == 0) continue;
      const cv::Vec3b& c = rgb.at<cv::Vec3b>(row, col);
      samples.push_back({Eigen::Vector2d(col, row), Eigen::Vector3f(c[0], c[1], c[2])});
    }
  }
  if (samples.empty()) return initial;
  const Eigen::Matrix2d to_lattice = stored.lattice.basis().inverse();
  const cv::Mat& tile = stored.tile_rgb;
  const auto cost = [&](const core::Similarity2& s) {
    double sum = 0.0;
    for (const Sample& sample : samples) {
      const Eigen::Vector2d c = to_lattice * s.apply(sample.point);
      sum += (sampleWrapped(tile, c.x() * tile.cols, c.y() * tile.rows) - sample.rgb).squaredNorm();
    }
    return sum;
  };
  // Steps: the turn and scale move the bitmap's far corner by about `reach` texels per unit.
  const double reach = std::hypot(rgb.cols, rgb.rows) / initial.scale();
  core::Similarity2 best = initial;
  double best_cost = cost(best);
  // Descent within a texel or so of the start (a wrong minimum a period away is not ours to
  // find): each step size walks at most kMaxWalk steps.
  constexpr int kMaxWalk = 16;
  for (double step = 1.0; step >= 0.125; step *= 0.5) {  // in texels at the far corner
    for (int walk = 0, improved = 1; improved != 0 && walk < kMaxWalk; ++walk) {
      improved = 0;
      for (int k = 0; k < 4; ++k) {
        for (const double sign : {-1.0, 1.0}) {
          core::Similarity2 s = best;
          const double d = sign * step;
          if (k == 0) s.a += d * initial.scale() / reach;
          if (k == 1) s.b += d * initial.scale() / reach;
          if (k == 2) s.tx += d * initial.scale();
          if (k == 3) s.ty += d * initial.scale();
          const double c = cost(s);
          if (c < best_cost) best_cost = c, best = s, improved = 1;
        }
      }
    }
  }
  return best;
}

}  // namespace tessera::match
