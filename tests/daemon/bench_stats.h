#pragma once
// The statistics the daemon's benchmarks report over their repetitions (cycle_bench.cc,
// plant/forwarder_bench.cc): nearest-rank percentiles, and the registration they share.

#include <benchmark/benchmark.h>

#include <algorithm>
#include <cmath>
#include <vector>

namespace linecal::bench {

// Nearest-rank percentile of the repetitions (p95 of 50: the 48th smallest).
inline double Percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  const size_t rank = static_cast<size_t>(std::ceil(p * static_cast<double>(v.size())));
  return v[std::clamp<size_t>(rank, 1, v.size()) - 1];
}
inline double P95(const std::vector<double>& v) { return Percentile(v, 0.95); }
inline double Max(const std::vector<double>& v) { return Percentile(v, 1.0); }

// One cycle per repetition, wall time in ms, only the statistics printed (mean, median,
// stddev, cv, p95 and max over the repetitions).
inline benchmark::internal::Benchmark* Cycles(benchmark::internal::Benchmark* b, int repetitions) {
  return b->Unit(benchmark::kMillisecond)
      ->UseRealTime()
      ->Iterations(1)
      ->Repetitions(repetitions)
      ->ComputeStatistics("p95", P95)
      ->ComputeStatistics("max", Max)
      ->ReportAggregatesOnly(true);
}

}  // namespace linecal::bench
