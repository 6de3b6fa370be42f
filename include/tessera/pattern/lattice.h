#pragma once
// The period lattice of a texture from its autocorrelation's peaks: two shortest independent
// period vectors (a sheared basis for running-bond bricks), one period vector for stripes
// (a texture unchanged along one direction), or none.
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "tessera/core/lattice2.h"
#include "tessera/pattern/autocorrelation.h"

namespace tessera::pattern {

enum class Periodicity { kNone, kOneDirection, kTwoDirections };
// "none" | "periodic1" | "periodic2"
const char* periodicityName(Periodicity p);

struct LatticeConfig {
  double min_peak = 0.3;  // an autocorrelation peak below this is not a period
  // ... nor one lower than the highest peak by more than this: a near-repeat inside the true
  // tile (four almost equal floor tiles) correlates less than the true period does, and noise
  // lowers every true peak alike.
  double peak_drop = 0.15;
  double min_period_px = 2.0;  // shorter shifts are the peak around the origin
  // Stripes: the texture stays correlated at least this well along one direction.
  double stripe_rho = 0.9;
  double min_angle_deg = 20.0;      // between the two period vectors
  double repeat_error_ratio = 2.0;  // see estimateLattice
};

struct LatticeEstimate {
  Periodicity periodicity = Periodicity::kNone;
  // kTwoDirections: a reduced basis (|v1| <= |v2|, |v1.v2| <= |v1|^2 / 2).
  // kOneDirection: v1 across the stripes; v2 a unit vector along them.
  core::Lattice2 lattice;
  double score = 0.0;  // autocorrelation at the period vectors (the lower of the two)
};

// How badly the texture repeats over a shift: the mean squared colour difference between
// texels x and x + d, over all pairs and over the better 60 % (which an occluder does not
// reach). Lower is better; nothing: cannot tell.
struct RepeatCost {
  double mean = 0.0, trimmed = 0.0;
  double unrelated = 0.0;  // what two unrelated texels would cost: twice the colour variance
};
using RepeatError = std::function<std::optional<RepeatCost>(const Eigen::Vector2d&)>;

// The lattice of the autocorrelation's clear peaks. With `repeat_error`, only the clear peaks
// (at most the 64 shortest) whose repeat costs are both within config.repeat_error_ratio of
// the best ones (plus a floor) count: a near-repeat inside the true tile correlates almost as
// well in grey as the true period, but repeats its colours worse. Stripes must repeat along
// themselves as well as across.
LatticeEstimate estimateLattice(const Autocorrelation& acf, const LatticeConfig& config = {},
                                const RepeatError& repeat_error = {});

// Lagrange-Gauss reduction: the same lattice with the shortest basis, |v1| <= |v2|.
core::Lattice2 reduceBasis(core::Lattice2 lattice);

// Whether two lattices are the same within `tolerance` (pixels): every vector of each basis
// is an integer combination of the other basis within that distance.
bool sameLattice(const core::Lattice2& a, const core::Lattice2& b, double tolerance);

// The same for a one-direction estimate (period v1, invariant along the unit `along`): each
// vector of `truth` lies in {k v1 + t along} within the tolerance, and v1 in `truth`.
bool sameStripes(const Eigen::Vector2d& v1, const Eigen::Vector2d& along,
                 const core::Lattice2& truth, double tolerance);

}  // namespace tessera::pattern
