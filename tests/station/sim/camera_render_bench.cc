// Camera renderer speed: whole frames of the reference station (deploy/) as the reference
// car's cameras see it, with the car at the station origin. Built with the tests, run by
// hand (docs/simulator.md): build-dir/bin/camera_render_bench.
//
// Baseline, in the same process: unprojecting the (W+1) x (H+1) pixel-corner grid, the
// least work an exact renderer of that camera does.
#include <benchmark/benchmark.h>

#include <cstdio>
#include <cstdlib>
#include <string>

#include "station/camera/camera_model.h"
#include "station/model/car_model.h"
#include "station/model/station_layout.h"
#include "station/sim/camera_render.h"

namespace linecal {
namespace {

struct Setup {
  StationLayout layout;
  CarModel car;
};

const Setup& Reference() {
  static const Setup* setup = [] {
    const std::string root = LINECAL_SOURCE_DIR;
    absl::StatusOr<StationLayout> layout =
        ReadStationLayout(root + "/deploy/stations/reference.json");
    absl::StatusOr<CarModel> car = ReadCarModel(root + "/deploy/cars/reference.json");
    if (!layout.ok() || !car.ok()) {
      std::fprintf(stderr, "reference files: %s %s\n", layout.status().ToString().c_str(),
                   car.status().ToString().c_str());
      std::exit(2);
    }
    return new Setup{*std::move(layout), *std::move(car)};
  }();
  return *setup;
}

CameraModel Camera(const SensorModel& sensor) { return *CameraModel::Create(*sensor.intrinsics); }

// The defaults, or every distractor and camera effect at once (the hardest case of the
// detector test set of docs/acceptance.md).
CameraRenderOptions Options(bool effects, int threads) {
  CameraRenderOptions o;
  o.threads = threads;
  if (effects) {
    o.clutter = true;
    o.occluder_count = 3;
    o.illumination_gradient_ratio = 4.0;
    o.illumination_gradient_direction_deg = 30.0;
    o.vignetting = 0.3;
    o.blur_sigma_px = 1.0;
    o.gamma = 1.6;
    o.noise_sigma = 4.0;
    o.jpeg_quality = 80;
  }
  return o;
}

void BM_Render(benchmark::State& state, const char* sensor_name, bool effects) {
  const SensorModel& sensor = *Reference().car.FindSensor(sensor_name);
  const CameraModel camera = Camera(sensor);
  const CameraRenderOptions options = Options(effects, static_cast<int>(state.range(0)));
  std::uint64_t seed = 1;
  std::size_t features = 0;
  for (auto _ : state) {
    const absl::StatusOr<CameraFrame> frame =
        RenderCameraFrame(camera, sensor.T_car_sensor_nominal, Reference().layout, options, seed++);
    if (!frame.ok()) {
      state.SkipWithError(frame.status().ToString().c_str());
      return;
    }
    features = frame->features.size();
    benchmark::DoNotOptimize(frame->image8.pixels.data());
  }
  state.counters["features"] = static_cast<double>(features);
}

void BM_UnprojectCornerGrid(benchmark::State& state, const char* sensor_name) {
  const CameraModel camera = Camera(*Reference().car.FindSensor(sensor_name));
  const int width = camera.intrinsics().width, height = camera.intrinsics().height;
  for (auto _ : state) {
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    for (int j = 0; j <= height; ++j) {
      for (int i = 0; i <= width; ++i) {
        Eigen::Vector3d ray;
        if (camera.Unproject(Eigen::Vector2d(i - 0.5, j - 0.5), &ray)) sum += ray;
      }
    }
    benchmark::DoNotOptimize(sum);
  }
}

BENCHMARK_CAPTURE(BM_UnprojectCornerGrid, front_camera, "front_camera")
    ->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_Render, front_camera, "front_camera", false)
    ->Arg(1)
    ->Arg(2)
    ->ArgName("threads")
    ->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_Render, front_camera_effects, "front_camera", true)
    ->Arg(2)
    ->ArgName("threads")
    ->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_UnprojectCornerGrid, surround_left, "surround_left")
    ->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_Render, surround_left, "surround_left", false)
    ->Arg(1)
    ->Arg(2)
    ->ArgName("threads")
    ->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_Render, surround_left_effects, "surround_left", true)
    ->Arg(2)
    ->ArgName("threads")
    ->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace linecal

BENCHMARK_MAIN();
