// Figures kept over a whole run in bounded memory: quantiles from a log histogram against the
// exact nearest-rank values, and a thinned series whose trend is the full series' trend.
#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "tessera/core/quantiles.h"
#include "tessera/core/thinned_series.h"

namespace tessera::core {
namespace {

double exactQuantile(std::vector<double> values, double p) {
  std::sort(values.begin(), values.end());
  const auto rank = static_cast<std::size_t>(std::ceil(p * static_cast<double>(values.size())));
  return values[std::max<std::size_t>(rank, 1) - 1];
}

TEST(Quantiles, AreWithinHalfAPercentOfTheExactNearestRankValues) {
  std::mt19937 random(7);
  std::lognormal_distribution<double> latency_ms(4.0, 1.5);  // 0.1 ms to seconds
  Quantiles quantiles;
  std::vector<double> all;
  double sum = 0.0;
  for (int i = 0; i < 20000; ++i) {
    const double x = latency_ms(random);
    quantiles.add(x);
    all.push_back(x);
    sum += x;
  }
  for (const double p : {0.01, 0.5, 0.9, 0.95, 0.99, 1.0}) {
    const double exact = exactQuantile(all, p);
    EXPECT_NEAR(*quantiles.quantile(p), exact, 0.005 * exact) << "p = " << p;
  }
  EXPECT_EQ(quantiles.count(), 20000u);
  EXPECT_NEAR(quantiles.sum(), sum, 1e-9 * sum);
  EXPECT_DOUBLE_EQ(quantiles.last(), all.back());
}

TEST(Quantiles, CountZeroNegativeAndNanAsZeroAndSayNothingWhenEmpty) {
  Quantiles quantiles;
  EXPECT_FALSE(quantiles.quantile(0.5));
  for (const double x : {0.0, -3.0, std::nan(""), 5.0}) quantiles.add(x);
  EXPECT_EQ(*quantiles.quantile(0.75), 0.0);
  EXPECT_NEAR(*quantiles.quantile(1.0), 5.0, 0.025);
  EXPECT_DOUBLE_EQ(quantiles.sum(), 5.0);
}

TEST(ThinnedSeries, StaysWithinItsBoundAndKeepsTheTrendOfAMillionPoints) {
  ThinnedSeries series(1000);
  std::mt19937 random(11);
  std::normal_distribution<double> noise(0.0, 5.0);
  // Resident memory of a run: flat for the first half, then growing 0.02 MB per frame.
  const int n = 1000000;
  for (int i = 0; i < n; ++i) {
    const double growth = i < n / 2 ? 0.0 : 0.02 * (i - n / 2);
    series.add(i, 300.0 + growth + noise(random));
  }
  EXPECT_LE(series.points().size(), 1000u);
  EXPECT_GE(series.points().size(), 500u);
  EXPECT_EQ(series.added(), static_cast<std::size_t>(n));
  // Evenly spread: the last point kept is near the end.
  EXPECT_GT(series.points().back().x, n - 2.0 * n / 1000.0);
  EXPECT_NEAR(*leastSquaresSlope(series.points(), n / 2.0), 0.02, 0.001);
  // Over the whole series the slope is half the second half's (least squares of a hinge).
  EXPECT_NEAR(*leastSquaresSlope(series.points(), 0.0), 0.01, 0.001);
  EXPECT_FALSE(leastSquaresSlope(series.points(), 2.0 * n));
}

}  // namespace
}  // namespace tessera::core
