#include "tessera/pattern/lattice.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace tessera::pattern {

namespace {

constexpr double kPi = 3.14159265358979323846;

struct Peak {
  Eigen::Vector2d d;
  double rho = 0.0;
};

// Vertex offset of the parabola through (-1, a), (0, b), (1, c), within half a texel.
double parabolicOffset(double a, double b, double c) {
  const double denominator = a - 2.0 * b + c;
  if (!(denominator < 0.0)) return 0.0;
  return std::clamp(0.5 * (a - c) / denominator, -0.5, 0.5);
}

// How much higher that parabola's vertex is than b.
double parabolicRise(double a, double b, double c) {
  const double t = parabolicOffset(a, b, c);
  return 0.25 * (c - a) * t;
}

// The autocorrelation's highest integer shift within `window` of `near`, refined to a
// sub-texel position by a parabola along each axis.
std::optional<Peak> peakNear(const Autocorrelation& acf, const Eigen::Vector2d& near, int window) {
  std::optional<Peak> best;
  int bx = 0, by = 0;
  const int cx = static_cast<int>(std::lround(near.x())),
            cy = static_cast<int>(std::lround(near.y()));
  for (int dy = cy - window; dy <= cy + window; ++dy) {
    for (int dx = cx - window; dx <= cx + window; ++dx) {
      if (!acf.contains(dx, dy)) continue;
      const double r = acf.at(dx, dy);
      if (r > -1.0 && (!best || r > best->rho)) best = Peak{{dx, dy}, r}, bx = dx, by = dy;
    }
  }
  if (!best) return best;
  // The peak's position and height between texels: a parabola along each axis.
  const double centre = best->rho;
  if (acf.contains(bx - 1, by) && acf.contains(bx + 1, by)) {
    const double a = acf.at(bx - 1, by), c = acf.at(bx + 1, by);
    best->d.x() += parabolicOffset(a, centre, c);
    best->rho += parabolicRise(a, centre, c);
  }
  if (acf.contains(bx, by - 1) && acf.contains(bx, by + 1)) {
    const double a = acf.at(bx, by - 1), c = acf.at(bx, by + 1);
    best->d.y() += parabolicOffset(a, centre, c);
    best->rho += parabolicRise(a, centre, c);
  }
  return best;
}

// Local maxima of the autocorrelation on one half plane (rho is symmetric), away from the
// origin, at least `floor` high, sub-texel refined.
std::vector<Peak> findPeaks(const Autocorrelation& acf, double min_radius, double floor) {
  std::vector<Peak> peaks;
  for (int dy = 0; dy < acf.radius_y; ++dy) {
    for (int dx = -acf.radius_x + 1; dx < acf.radius_x; ++dx) {
      if (dy == 0 && dx <= 0) continue;
      if (std::hypot(dx, dy) < min_radius) continue;
      const float r = acf.at(dx, dy);
      if (r < floor) continue;
      bool highest = true;
      for (int ny = -1; ny <= 1 && highest; ++ny) {
        for (int nx = -1; nx <= 1; ++nx) {
          if ((nx != 0 || ny != 0) && acf.contains(dx + nx, dy + ny) &&
              acf.at(dx + nx, dy + ny) > r) {
            highest = false;
            break;
          }
        }
      }
      if (highest) {
        if (const auto refined = peakNear(acf, {dx, dy}, 0)) peaks.push_back(*refined);
      }
    }
  }
  return peaks;
}

// The vector refined through its largest multiple k v (k <= 4) that the autocorrelation
// still holds: a peak's position error divides by k.
Eigen::Vector2d refineByMultiples(const Autocorrelation& acf, const Eigen::Vector2d& v) {
  for (int k = 4; k >= 2; --k) {
    const Eigen::Vector2d far = k * v;
    if (std::abs(far.x()) + 1 > acf.radius_x || std::abs(far.y()) + 1 > acf.radius_y) continue;
    const auto peak = peakNear(acf, far, 1);
    if (peak && peak->rho > -1.0 && (peak->d - far).norm() <= 1.5) return peak->d / k;
  }
  return v;
}

// How well the texture repeats over a lattice: the mean autocorrelation peak at its short
// vectors v1, v2, v1 + v2 and v1 - v2 (those within reach); -1 when none is.
double latticeScore(const Autocorrelation& acf, const core::Lattice2& l) {
  double sum = 0.0;
  int count = 0;
  for (const Eigen::Vector2d& d :
       {l.v1, l.v2, Eigen::Vector2d(l.v1 + l.v2), Eigen::Vector2d(l.v1 - l.v2)}) {
    if (std::abs(d.x()) + 1 > acf.radius_x || std::abs(d.y()) + 1 > acf.radius_y) continue;
    const auto peak = peakNear(acf, d, 1);
    if (!peak || peak->rho <= -1.0) continue;
    sum += peak->rho;
    ++count;
  }
  return count > 0 ? sum / count : -1.0;
}

// The least rho along direction u over shifts min_t .. max_t.
double leastAlong(const Autocorrelation& acf, const Eigen::Vector2d& u, double min_t,
                  double max_t) {
  double least = 1.0;
  for (double t = min_t; t <= max_t; t += 1.0) {
    least = std::min(least, acf.sample(t * u.x(), t * u.y()));
  }
  return least;
}

// Stripes: a direction along which the texture does not change (rho stays high), while it
// does across. Returns the unit vector along the stripes.
std::optional<Eigen::Vector2d> stripeDirection(const Autocorrelation& acf,
                                               const LatticeConfig& config) {
  const double reach =
      std::max(config.min_period_px + 2.0, 0.5 * std::min(acf.radius_x, acf.radius_y));
  double best_rho = -1.0, best_angle = 0.0;
  for (double angle = 0.0; angle < 180.0; angle += 2.0) {
    const double a = angle * kPi / 180.0;
    const double r = leastAlong(acf, {std::cos(a), std::sin(a)}, 1.0, reach);
    if (r > best_rho) best_rho = r, best_angle = angle;
  }
  for (double angle = best_angle - 1.75; angle <= best_angle + 1.75; angle += 0.25) {
    const double a = angle * kPi / 180.0;
    const double r = leastAlong(acf, {std::cos(a), std::sin(a)}, 1.0, reach);
    if (r > best_rho) best_rho = r, best_angle = angle;
  }
  if (best_rho < config.stripe_rho) return std::nullopt;
  const double a = best_angle * kPi / 180.0;
  const Eigen::Vector2d along(std::cos(a), std::sin(a));
  // A smooth texture correlates with every short shift: stripes do not across.
  if (leastAlong(acf, {-along.y(), along.x()}, 1.0, reach) >= config.stripe_rho - 0.2) {
    return std::nullopt;
  }
  return along;
}

// The period across stripes: the first clear peak of rho along `across`.
std::optional<Peak> periodAcross(const Autocorrelation& acf, const Eigen::Vector2d& across,
                                 const LatticeConfig& config) {
  const double step = 0.25;
  std::vector<double> profile;
  for (double t = 0.0;; t += step) {
    const double r = acf.sample(t * across.x(), t * across.y());
    if (r <= -1.0) break;
    profile.push_back(r);
  }
  double highest = -1.0;
  const auto first = static_cast<std::size_t>(std::ceil((config.min_period_px - 0.5) / step));
  for (std::size_t i = first; i + 1 < profile.size(); ++i) highest = std::max(highest, profile[i]);
  const double floor = std::max(config.min_peak, highest - config.peak_drop);
  for (std::size_t i = std::max<std::size_t>(first, 1); i + 1 < profile.size(); ++i) {
    if (profile[i] >= floor && profile[i] >= profile[i - 1] && profile[i] >= profile[i + 1]) {
      const double t =
          (static_cast<double>(i) + parabolicOffset(profile[i - 1], profile[i], profile[i + 1])) *
          step;
      return Peak{t * across, profile[i]};
    }
  }
  return std::nullopt;
}

// Whether cost `e` is within `ratio` of the best, plus a floor: 0.3 % of what unrelated texels
// cost (what resampling between texels costs an exact period), and at least one grey level
// in each channel, so that a lossless image's exact zero does not make every other shift fail.
double repeatFloor(const RepeatCost& e) { return std::max(3.0, 0.003 * e.unrelated); }
bool within(double e, double best, double ratio, double floor) { return e <= ratio * best + floor; }
bool repeatsAsWell(const RepeatCost& e, const RepeatCost& best, double ratio) {
  const double floor = repeatFloor(e);
  return within(e.mean, best.mean, ratio, floor) && within(e.trimmed, best.trimmed, ratio, floor);
}

double cross(const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
  return a.x() * b.y() - a.y() * b.x();
}

}  // namespace

const char* periodicityName(Periodicity p) {
  switch (p) {
    case Periodicity::kTwoDirections:
      return "periodic2";
    case Periodicity::kOneDirection:
      return "periodic1";
    case Periodicity::kNone:
      break;
  }
  return "none";
}

core::Lattice2 reduceBasis(core::Lattice2 lattice) {
  Eigen::Vector2d& a = lattice.v1;
  Eigen::Vector2d& b = lattice.v2;
  if (a.squaredNorm() > b.squaredNorm()) std::swap(a, b);
  for (int iteration = 0; iteration < 64 && a.squaredNorm() > 0.0; ++iteration) {
    const double mu = std::round(a.dot(b) / a.squaredNorm());
    b -= mu * a;
    if (b.squaredNorm() >= a.squaredNorm()) break;
    std::swap(a, b);
  }
  // Canonical signs: v1 points to +x (or +y when vertical); v1 x v2 > 0.
  if (a.x() < 0.0 || (a.x() == 0.0 && a.y() < 0.0)) a = -a;
  if (cross(a, b) < 0.0) b = -b;
  return lattice;
}

bool sameLattice(const core::Lattice2& a, const core::Lattice2& b, double tolerance) {
  if (a.cellArea() < 1e-9 || b.cellArea() < 1e-9) return false;
  const auto generates = [tolerance](const core::Lattice2& basis, const Eigen::Vector2d& w) {
    const Eigen::Vector2d c = basis.coordinatesOf(w);
    const Eigen::Vector2d n(std::round(c.x()), std::round(c.y()));
    return (basis.basis() * n - w).norm() <= tolerance;
  };
  return generates(a, b.v1) && generates(a, b.v2) && generates(b, a.v1) && generates(b, a.v2);
}

bool sameStripes(const Eigen::Vector2d& v1, const Eigen::Vector2d& along,
                 const core::Lattice2& truth, double tolerance) {
  const Eigen::Vector2d across(-along.y(), along.x());
  const double period = v1.dot(across);
  if (std::abs(period) < 1e-9 || truth.cellArea() < 1e-9) return false;
  for (const Eigen::Vector2d& w : {truth.v1, truth.v2}) {
    const double k = std::round(w.dot(across) / period);
    if (std::abs(w.dot(across) - k * period) > tolerance) return false;
  }
  const Eigen::Vector2d c = truth.coordinatesOf(v1);
  const Eigen::Vector2d n(std::round(c.x()), std::round(c.y()));
  return (truth.basis() * n - v1).norm() <= tolerance;
}

LatticeEstimate estimateLattice(const Autocorrelation& acf, const LatticeConfig& config,
                                const RepeatError& repeat_error) {
  LatticeEstimate estimate;
  if (acf.radius_x < 2 || acf.radius_y < 2) return estimate;

  if (const auto along = stripeDirection(acf, config)) {
    const Eigen::Vector2d across(-along->y(), along->x());
    const auto period = periodAcross(acf, across, config);
    // In colour too, stripes repeat along themselves as well as across.
    bool repeats_along = true;
    if (period && repeat_error) {
      const auto e_across = repeat_error(period->d);
      const auto e_along = repeat_error(std::max(8.0, period->d.norm()) * *along);
      repeats_along =
          e_across && e_along && repeatsAsWell(*e_along, *e_across, config.repeat_error_ratio);
    }
    if (period && repeats_along) {
      estimate.periodicity = Periodicity::kOneDirection;
      const double t = refineByMultiples(acf, period->d).dot(across);
      estimate.lattice = {t * across, *along};
      if (estimate.lattice.v1.x() < 0.0 ||
          (estimate.lattice.v1.x() == 0 && estimate.lattice.v1.y() < 0))
        estimate.lattice.v1 = -estimate.lattice.v1;
      estimate.score = period->rho;
      return estimate;
    }
  }

  std::vector<Peak> peaks = findPeaks(acf, config.min_period_px, config.min_peak);
  if (peaks.empty()) return estimate;
  std::sort(peaks.begin(), peaks.end(), [](const Peak& a, const Peak& b) {
    const double la = a.d.squaredNorm(), lb = b.d.squaredNorm();
    return la != lb ? la < lb : a.rho > b.rho;
  });
  double highest = 0.0;
  for (const Peak& p : peaks) highest = std::max(highest, p.rho);
  double floor = std::max(config.min_peak, highest - config.peak_drop);
  constexpr double kUnknown = std::numeric_limits<double>::infinity();
  RepeatCost best{kUnknown, kUnknown};
  if (repeat_error) {
    // Clear peaks whose colours repeat worse than the best ones are dropped.
    constexpr std::size_t kMaxJudged = 64;
    std::vector<std::pair<Peak*, RepeatCost>> judged;
    for (Peak& p : peaks) {
      if (p.rho < floor) continue;
      if (judged.size() == kMaxJudged) {
        p.rho = -1.0;
        continue;
      }
      const auto e = repeat_error(p.d);
      judged.emplace_back(&p, e ? *e : RepeatCost{kUnknown, kUnknown});
    }
    // The trimmed cost first: an occluder raises every long shift's mean cost (its pairs
    // with the pattern fail), so the mean is compared only among the shifts whose better
    // 60 % repeat as well as the best's, where it catches a near-repeat that differs over
    // less than the trimmed share of the texels.
    for (const auto& [p, e] : judged) best.trimmed = std::min(best.trimmed, e.trimmed);
    for (const auto& [p, e] : judged) {
      if (within(e.trimmed, best.trimmed, config.repeat_error_ratio, repeatFloor(e))) {
        best.mean = std::min(best.mean, e.mean);
      }
    }
    for (auto& [p, e] : judged) {
      if (!repeatsAsWell(e, best, config.repeat_error_ratio)) p->rho = -1.0;
    }
    std::erase_if(peaks, [](const Peak& p) { return p.rho < 0.0; });
    if (peaks.empty()) return estimate;
  }
  const auto first =
      std::find_if(peaks.begin(), peaks.end(), [floor](const Peak& p) { return p.rho >= floor; });
  if (first == peaks.end()) return estimate;
  // The second vector: the shortest clear peak in another direction, else any peak there
  // (an occluder or a gradient can weaken one direction more than the other).
  const double min_sin = std::sin(config.min_angle_deg * kPi / 180.0);
  const auto independent = [&](const Peak& p) {
    return std::abs(cross(first->d, p.d)) >= min_sin * first->d.norm() * p.d.norm();
  };
  auto second = std::find_if(peaks.begin(), peaks.end(),
                             [&](const Peak& p) { return p.rho >= floor && independent(p); });
  if (second == peaks.end() && repeat_error) {
    // Among those, one whose colours repeat (over the better 60 %, which an occluder that
    // weakened the peak does not reach) as well as the clear peaks' do.
    constexpr int kMaxFallbacks = 16;
    int tried = 0;
    second = std::find_if(peaks.begin(), peaks.end(), [&](const Peak& p) {
      if (!independent(p) || tried >= kMaxFallbacks) return false;
      ++tried;
      const auto e = repeat_error(p.d);
      return e && within(e->trimmed, best.trimmed, config.repeat_error_ratio, repeatFloor(*e));
    });
  }
  if (second == peaks.end()) second = std::find_if(peaks.begin(), peaks.end(), independent);
  if (second == peaks.end()) {  // one direction of repeats, but the texture changes along it
    estimate.periodicity = Periodicity::kOneDirection;
    const Eigen::Vector2d v = refineByMultiples(acf, first->d);
    estimate.lattice = {v, Eigen::Vector2d(-v.y(), v.x()).normalized()};
    estimate.score = first->rho;
    return estimate;
  }
  core::Lattice2 lattice = reduceBasis({first->d, second->d});
  lattice.v1 = refineByMultiples(acf, lattice.v1);
  lattice.v2 = refineByMultiples(acf, lattice.v2);
  estimate.periodicity = Periodicity::kTwoDirections;
  estimate.lattice = reduceBasis(lattice);
  estimate.score = latticeScore(acf, estimate.lattice);
  return estimate;
}

}  // namespace tessera::pattern
