// Speed of the round-hole board in point clouds (docs/acceptance.md: <= 50 ms per frame): the
// prior-free search over the scenes of round_hole_search_test.cc (the board on its stand, the
// floor, a wall behind it and a board-sized box beside it, 10 rotations of the reference car's
// Pandar64 or VLP-16). Baseline in the same process: the same frames through the detector
// given the board's true pose as its prior (what the station runs with its planned pose), so
// the search's own cost is the difference. The counter s_per_frame is the bar's number.
//   build/bin/round_hole_bench --benchmark_repetitions=5 --benchmark_report_aggregates_only=true
#include <benchmark/benchmark.h>

#include <map>
#include <span>
#include <vector>

#include "detectors/round_hole/round_hole_search.h"
#include "tests/detectors/round_hole/round_hole_scene.h"

namespace linecal {
namespace {

// The cases of RoundHoleSearchTest.FindsTheBoardAmongFloorWallAndABox.
const Case kCases[] = {
    {"roof_lidar", 3.0, 0.0, 0.0, 0.02, 0.01},       {"roof_lidar", 5.0, 120.0, 30.0, 0.03, 0.01},
    {"roof_lidar", 8.0, -70.0, -35.0, 0.02, 0.01},   {"bumper_lidar", 3.0, 200.0, 25.0, 0.02, 0.02},
    {"bumper_lidar", 5.0, -30.0, -20.0, 0.02, 0.02}, {"bumper_lidar", 8.0, 60.0, 10.0, 0.02, 0.02},
};

// Each case's scene, simulated once for all benchmarks.
const Scene& SceneOf(int index) {
  static std::map<int, Scene> scenes;
  auto it = scenes.find(index);
  if (it == scenes.end()) {
    const Case& c = kCases[index];
    it = scenes.emplace(index, SimulateLayout(Beams(c.sensor), BoardWallAndBox(c), c.sigma_m, 10))
             .first;
  }
  return it->second;
}

// Runs detect(frames) per iteration; fails the benchmark when the board is not found, so a
// fast wrong answer never reads as speed.
template <typename Detect>
void RunOn(benchmark::State& state, Detect&& detect) {
  const Scene& scene = SceneOf(static_cast<int>(state.range(0)));
  const std::vector<std::span<const RoundHoleCloudPoint>> views(scene.frames.begin(),
                                                                scene.frames.end());
  const std::span<const std::span<const RoundHoleCloudPoint>> frames(views);
  for (auto _ : state) {
    if (!detect(scene, frames)) {
      state.SkipWithError("the board was not found");
      return;
    }
  }
  const Case& c = kCases[state.range(0)];
  state.SetLabel(std::string(c.sensor) + " " + std::to_string(static_cast<int>(c.distance_m)) +
                 " m");
  state.counters["s_per_frame"] = benchmark::Counter(
      static_cast<double>(views.size()),
      benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
}

void BM_Search(benchmark::State& state) {
  RunOn(state, [](const Scene& scene, auto frames) {
    return SearchRoundHoleBoardInCloud(scene.board, frames).found;
  });
}

void BM_DetectWithTruePriorBaseline(benchmark::State& state) {
  RunOn(state, [](const Scene& scene, auto frames) {
    return DetectRoundHoleBoardInCloud(scene.board, frames, scene.T_lidar_board).found;
  });
}

BENCHMARK(BM_Search)->DenseRange(0, 5)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_DetectWithTruePriorBaseline)->DenseRange(0, 5)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace linecal

BENCHMARK_MAIN();
