// Speed of the simulator's LiDAR: one rotation of each model in the reference station
// (acceptance: a Pandar64 rotation in <= 200 ms). Baseline in the same process: the same
// rotation cast against the floor only, i.e. the cost of the beam loop, ray directions and
// the point output without the station's boards, stands and walls.
//   build/bin/lidar_sim_bench --benchmark_repetitions=5 --benchmark_report_aggregates_only=true
#include <benchmark/benchmark.h>

#include <string>

#include "station/model/car_model.h"
#include "station/model/station_layout.h"
#include "station/sim/lidar_sim.h"

namespace linecal {
namespace {

const std::string kDeploy = std::string(LINECAL_SOURCE_DIR) + "/deploy";

void Run(benchmark::State& state, const char* sensor, bool floor_only) {
  StationLayout station = *ReadStationLayout(kDeploy + "/stations/reference.json");
  if (floor_only) {
    station.boards.clear();
    station.surfaces.clear();
  }
  const CarModel car = *ReadCarModel(kDeploy + "/cars/reference.json");
  const SensorModel* s = car.FindSensor(sensor);
  const LidarModel model = *LidarModelFromName(s->model);
  const LidarBeamTable beams =
      *(s->angles_file.empty() ? DefaultBeamTable(model)
                               : ReadAngleCorrectionCsv(model, s->angles_file));
  LidarSimOptions options;
  size_t points = 0;
  for (auto _ : state) {
    absl::StatusOr<LidarSimResult> r =
        SimulateLidar(beams, s->T_car_sensor_nominal, station, options, 0, 1);
    points = r->scans[0].points.size();
    benchmark::DoNotOptimize(points);
  }
  state.counters["points"] = static_cast<double>(points);
}

BENCHMARK_CAPTURE(Run, pandar64_station, "roof_lidar", false)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(Run, pandar64_floor_only_baseline, "roof_lidar", true)
    ->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(Run, vlp16_station, "bumper_lidar", false)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(Run, vlp16_floor_only_baseline, "bumper_lidar", true)
    ->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace linecal

BENCHMARK_MAIN();
