// Radar decoding throughput: frames/s for ARS408 cluster lists and ESR scans, decoding only
// (the frames are built once, in memory). Run by hand: build-dir/bin/radar_decoder_bench.
#include <benchmark/benchmark.h>

#include <numbers>
#include <random>

#include "station/sensors/radar/radar_decoder.h"

namespace linecal {
namespace {

// 100 measurement cycles, a realistic recording length for one station cycle (~7 s of
// ARS408 at 72 ms or 5 s of ESR at 50 ms).
constexpr int kCycles = 100;

std::vector<CanFrame> MakeFrames(RadarModel model) {
  std::mt19937 rng(1);  // fixed seed
  std::uniform_real_distribution<double> range(2, 90), azimuth(-0.8, 0.8), rate(-10, 10);
  std::vector<CanFrame> frames;
  for (int k = 0; k < kCycles; ++k) {
    RadarCycle c;
    c.counter = static_cast<uint32_t>(k);
    c.time = CanTime(std::chrono::milliseconds(50 * k));
    c.kind = model == RadarModel::kEsr ? RadarDetectionKind::kTrack : RadarDetectionKind::kCluster;
    // ARS408: 100 clusters with quality (a busy hall); ESR: 32 of its 64 track slots used.
    const int n = model == RadarModel::kEsr ? 32 : 100;
    for (int i = 0; i < n; ++i) {
      RadarDetection d;
      d.kind = c.kind;
      d.id = model == RadarModel::kEsr ? 2 * i + 1 : i;
      d.range_m = range(rng);
      d.azimuth_rad = azimuth(rng);
      d.range_rate_mps = rate(rng);
      if (model == RadarModel::kArs408) {
        d.rcs_dbsm = 10;
        d.cluster_quality = Ars408ClusterQuality{};
      }
      c.detections.push_back(d);
    }
    const absl::StatusOr<std::vector<CanFrame>> encoded =
        model == RadarModel::kEsr ? EncodeEsrScan(c, "can0", {}) : EncodeArs408Cycle(c, "can0", {});
    frames.insert(frames.end(), encoded->begin(), encoded->end());
  }
  return frames;
}

void BM_Decode(benchmark::State& state, RadarModel model) {
  const std::vector<CanFrame> frames = MakeFrames(model);
  int64_t detections = 0;
  for (auto _ : state) {
    const RadarDecodeResult r = DecodeRadarFrames(frames, model, {});
    detections += r.stats.detections;
    benchmark::DoNotOptimize(r.cycles.data());
  }
  state.SetItemsProcessed(state.iterations() * static_cast<int64_t>(frames.size()));
  state.counters["frames/s"] = benchmark::Counter(
      static_cast<double>(state.iterations() * static_cast<int64_t>(frames.size())),
      benchmark::Counter::kIsRate);
  state.counters["detections/s"] =
      benchmark::Counter(static_cast<double>(detections), benchmark::Counter::kIsRate);
}

BENCHMARK_CAPTURE(BM_Decode, ars408_clusters, RadarModel::kArs408);
BENCHMARK_CAPTURE(BM_Decode, esr_tracks, RadarModel::kEsr);

// candump text → frames, the other half of `linecal radar decode`.
void BM_ParseCandump(benchmark::State& state) {
  std::string text;
  for (const CanFrame& f : MakeFrames(RadarModel::kArs408)) text += *FormatCandumpLine(f) + "\n";
  int64_t frames = 0;
  for (auto _ : state) {
    const absl::StatusOr<std::vector<CanFrame>> parsed = ParseCandumpLog(text, "bench");
    frames += static_cast<int64_t>(parsed->size());
    benchmark::DoNotOptimize(parsed->data());
  }
  state.counters["frames/s"] =
      benchmark::Counter(static_cast<double>(frames), benchmark::Counter::kIsRate);
  state.SetBytesProcessed(state.iterations() * static_cast<int64_t>(text.size()));
}
BENCHMARK(BM_ParseCandump);

}  // namespace
}  // namespace linecal

BENCHMARK_MAIN();
