// The soak's memory verdict (reliability_support.h, JudgeMemoryGrowth) on synthetic series
// shaped like the soak's: samples every 10 cycles from cycle 100 to 1000. A resident set
// wandering in the 51-88 MB band of the 1,000-cycle soak, with or without memory between
// samples, passes; steady growth fails, in the resident set and in the heap.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include "tests/daemon/reliability/reliability_support.h"

namespace linecal::reliability {
namespace {

std::vector<double> Cycles() {
  std::vector<double> x;
  for (int c = 100; c <= 1000; c += 10) x.push_back(c);
  return x;
}

// The RSS verdict as the soak gives it: the bound is 5% of the line's level at cycle 100.
MemoryGrowth JudgeRss(const std::vector<double>& x, const std::vector<double>& y) {
  const LinearTrend t = FitLinearTrend(x, y);
  return JudgeMemoryGrowth(x, y, kSoakRssGrowthFractionPer1000 * (t.intercept + t.slope * x[0]),
                           kSoakMinSignificance);
}

TEST(MemoryTrendTest, FitRecoversALine) {
  const std::vector<double> x = {0, 1, 2, 3};
  const LinearTrend t = FitLinearTrend(x, {1, 3, 5, 7});
  EXPECT_DOUBLE_EQ(t.slope, 2);
  EXPECT_DOUBLE_EQ(t.intercept, 1);
  EXPECT_NEAR(t.scatter, 0, 1e-12);
  EXPECT_EQ(t.samples, 4);
  EXPECT_EQ(FitLinearTrend({5, 5, 5}, {1, 2, 3}).samples, 0);  // one x only: no line
  // Residuals alternating in sign: no memory; in runs: memory, and a wider slope error.
  const std::vector<double> x8 = {0, 1, 2, 3, 4, 5, 6, 7};
  const LinearTrend alternating = FitLinearTrend(x8, {1, -1, 1, -1, 1, -1, 1, -1});
  const LinearTrend runs = FitLinearTrend(x8, {1, 1, 1, -1, -1, -1, 1, 1});
  EXPECT_EQ(alternating.autocorrelation, 0);
  EXPECT_GT(runs.autocorrelation, 0.1);
  EXPECT_GT(runs.slope_error, runs.scatter / std::sqrt(42.0));  // sum (x - 3.5)^2 = 42
}

// Independent draws over the band, and a band with memory (each sample 0.9 of the last's
// distance from the middle plus noise): no trend, 20 seeds each.
TEST(MemoryTrendTest, ResidentSetWanderingInABandPasses) {
  const std::vector<double> x = Cycles();
  for (unsigned seed = 1; seed <= 20; ++seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> band(51, 88);
    std::normal_distribution<double> step(0, 5);
    std::vector<double> flat, wander;
    double w = 70;
    for (size_t i = 0; i < x.size(); ++i) {
      flat.push_back(band(rng));
      w = std::clamp(69.5 + 0.9 * (w - 69.5) + step(rng), 51.0, 88.0);
      wander.push_back(w);
    }
    const MemoryGrowth f = JudgeRss(x, flat), g = JudgeRss(x, wander);
    EXPECT_FALSE(f.leak) << "seed " << seed << ": " << f.growth_per_1000 << " MB/1000, "
                         << f.significance << " standard errors";
    EXPECT_FALSE(g.leak) << "seed " << seed << ": " << g.growth_per_1000 << " MB/1000, "
                         << g.significance << " standard errors";
  }
}

// 40 kB per cycle under the same band's noise: 36 MB over the run, found.
TEST(MemoryTrendTest, ResidentSetGrowingSteadilyFails) {
  const std::vector<double> x = Cycles();
  for (unsigned seed = 1; seed <= 20; ++seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> noise(-18.5, 18.5);
    std::vector<double> y;
    for (double c : x) y.push_back(60 + 0.04 * c + noise(rng));
    const MemoryGrowth g = JudgeRss(x, y);
    EXPECT_TRUE(g.leak) << "seed " << seed << ": " << g.growth_per_1000 << " MB/1000, "
                        << g.significance << " standard errors";
    EXPECT_NEAR(g.growth_per_1000, 40, 12);
  }
}

// Heap in use: 5 kB per cycle over 8 MB with 0.3 MB of noise fails; the 1,000-cycle soak's
// 7.8 -> 9.4 MB rising and levelling off (a page cache filling up) passes.
TEST(MemoryTrendTest, HeapGrowingSteadilyFailsAndACacheFillingUpPasses) {
  const std::vector<double> x = Cycles();
  std::mt19937 rng(7);
  std::normal_distribution<double> noise(0, 0.3);
  std::vector<double> leak, cache;
  for (double c : x) {
    leak.push_back(8 + 0.005 * c + noise(rng));
    cache.push_back(7.8 + 1.6 * (1 - std::exp(-(c - 100) / 300)) + noise(rng));
  }
  const MemoryGrowth l = JudgeMemoryGrowth(x, leak, kSoakHeapGrowthMbPer1000, kSoakMinSignificance);
  const MemoryGrowth c =
      JudgeMemoryGrowth(x, cache, kSoakHeapGrowthMbPer1000, kSoakMinSignificance);
  EXPECT_TRUE(l.leak) << l.growth_per_1000 << " MB/1000";
  EXPECT_NEAR(l.growth_per_1000, 5, 0.5);
  EXPECT_FALSE(c.leak) << c.growth_per_1000 << " MB/1000";
}

}  // namespace
}  // namespace linecal::reliability
