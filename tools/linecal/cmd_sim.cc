// linecal sim: renders one car in a station and writes a capture (docs/simulator.md).
#include <cstdio>
#include <nlohmann/json.hpp>
#include <string>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "station/sim/simulator.h"
#include "tools/cli/command_line.h"
#include "tools/linecal/commands.h"

namespace linecal::tools {
namespace {

constexpr char kCommand[] = "sim";

// Reads numeric option `name` into *slot when given; the error names the option.
template <typename T>
absl::Status ReadNumber(const cli::CommandLine& cl, const std::string& name, T* slot) {
  if constexpr (std::is_integral_v<T>) {
    absl::StatusOr<int> v = cl.GetInt(name, static_cast<int>(*slot));
    if (!v.ok()) return v.status();
    *slot = static_cast<T>(*v);
  } else {
    absl::StatusOr<double> v = cl.GetDouble(name, *slot);
    if (!v.ok()) return v.status();
    *slot = *v;
  }
  return absl::OkStatus();
}

}  // namespace

int RunSim(const Args& args) {
  cli::CommandLine cl(
      "linecal sim --station FILE --car FILE --out DIR [--seed N] [options]",
      "Simulates one car in a station: every sensor of the car model is rendered (cameras), "
      "ray-cast "
      "(LiDARs) or simulated (radars) from its true mounting = nominal + a random error, and "
      "written "
      "as a capture (docs/capture-format.md) with ground_truth.json beside it.",
      {{"station", "FILE", "station layout (e.g. deploy/stations/reference.json)", true},
       {"car", "FILE", "car model (e.g. deploy/cars/reference.json)", true},
       {"out", "DIR", "capture directory to write", true},
       {"seed", "N", "random seed (default 1); the same seed gives the same capture"},
       {"vin", "VIN", "the car's VIN (default 1M8GDM9AXKP042788)"},
       {"sensors", "A,B", "simulate only these sensors"},
       {"perturb-angle-deg", "A", "mounting error bound per angle, degrees (default 0.5)"},
       {"perturb-offset-m", "M", "mounting error bound per position axis, metres (default 0.01)"},
       {"aligner-offset-m", "M", "aligner offset bound, metres (default 0.02)"},
       {"aligner-thrust-deg", "A", "aligner thrust angle bound, degrees (default 0.2)"},
       {"frames", "N", "frames per camera (default 1)"},
       {"noise", "SIGMA", "camera noise, grey levels (default 0)"},
       {"blur", "SIGMA", "camera blur, pixels (default 0)"},
       {"gamma", "G", "camera encoding gamma (default 1)"},
       {"gradient", "RATIO", "illumination gradient across the image, 1..4 (default 1)"},
       {"vignetting", "V", "vignetting strength 0..1 (default 0)"},
       {"jpeg", "Q", "JPEG-like quantisation quality 80..100 (default off)"},
       {"occluders", "N", "occluders per camera frame (default 0)"},
       {"clutter", "", "clutter texture on the walls"},
       {"bit-depth", "8|16", "camera PNG bit depth (default 8)"},
       {"lidar-rotations", "N", "LiDAR rotations (default 1)"},
       {"lidar-noise-m", "SIGMA", "LiDAR range noise, metres (default 0.02)"},
       {"lidar-dropout", "P", "LiDAR dropout probability (default 0)"},
       {"radar-cycles", "N", "radar measurement cycles (default 20)"},
       {"radar-azimuth-sigma-deg", "SIGMA",
        "radar azimuth noise per detection, degrees (default 0.1)"},
       {"json", "", "print the summary as JSON"}});
  if (auto code = cli::ParseOrExit(cl, kCommand, args)) return *code;

  SimulatorOptions o;
  o.vin = cl.Get("vin", o.vin);
  int seed = 1;
  for (const absl::Status& s :
       {ReadNumber(cl, "seed", &seed), ReadNumber(cl, "perturb-angle-deg", &o.perturb_angle_deg),
        ReadNumber(cl, "perturb-offset-m", &o.perturb_offset_m),
        ReadNumber(cl, "aligner-offset-m", &o.aligner_offset_m),
        ReadNumber(cl, "aligner-thrust-deg", &o.aligner_thrust_deg),
        ReadNumber(cl, "frames", &o.camera_frames), ReadNumber(cl, "noise", &o.camera.noise_sigma),
        ReadNumber(cl, "blur", &o.camera.blur_sigma_px), ReadNumber(cl, "gamma", &o.camera.gamma),
        ReadNumber(cl, "gradient", &o.camera.illumination_gradient_ratio),
        ReadNumber(cl, "vignetting", &o.camera.vignetting),
        ReadNumber(cl, "jpeg", &o.camera.jpeg_quality),
        ReadNumber(cl, "occluders", &o.camera.occluder_count),
        ReadNumber(cl, "bit-depth", &o.camera.bit_depth),
        ReadNumber(cl, "lidar-rotations", &o.lidar.rotations),
        ReadNumber(cl, "lidar-noise-m", &o.lidar.range_sigma_m),
        ReadNumber(cl, "lidar-dropout", &o.lidar.dropout_probability),
        ReadNumber(cl, "radar-cycles", &o.radar.cycles),
        ReadNumber(cl, "radar-azimuth-sigma-deg", &o.radar.azimuth_sigma_deg)}) {
    if (!s.ok()) return cli::BadInput(kCommand, std::string(s.message()));
  }
  if (seed < 0) return cli::BadInput(kCommand, absl::StrCat("--seed: must be >= 0, got ", seed));
  o.camera.clutter = cl.Has("clutter");
  if (cl.Has("sensors")) o.sensors = absl::StrSplit(cl.Get("sensors"), ',', absl::SkipEmpty());
  if (absl::Status s = o.Validate(); !s.ok())
    return cli::BadInput(kCommand, std::string(s.message()));

  absl::StatusOr<StationLayout> station = ReadStationLayout(cl.Get("station"));
  if (!station.ok()) return cli::BadInput(kCommand, std::string(station.status().message()));
  absl::StatusOr<CarModel> car = ReadCarModel(cl.Get("car"));
  if (!car.ok()) return cli::BadInput(kCommand, std::string(car.status().message()));

  const std::string out = cl.Get("out");
  absl::StatusOr<SimulationSummary> sim =
      SimulateCapture(*station, *car, o, static_cast<std::uint64_t>(seed), out,
                      [](int done, int all, const std::string& name) {
                        std::fprintf(stderr, "sim: [%d/%d] %s\n", done, all, name.c_str());
                      });
  if (!sim.ok()) {
    if (sim.status().code() == absl::StatusCode::kInvalidArgument) {
      return cli::BadInput(kCommand, std::string(sim.status().message()));
    }
    std::fprintf(stderr, "linecal sim: %s\n", std::string(sim.status().message()).c_str());
    return cli::kExitNegative;
  }
  const CaptureManifest& m = sim->manifest;
  if (cl.Has("json")) {
    nlohmann::json sensors = nlohmann::json::array();
    for (const CaptureSensor& s : m.sensors)
      sensors.push_back({{"name", s.name}, {"kind", SensorKindName(s.kind)}});
    std::printf("%s\n",
                nlohmann::json{{"capture", out},
                               {"vin", m.vin},
                               {"seed", seed},
                               {"sensors", sensors},
                               {"ground_truth", std::string(out) + "/" + kCaptureGroundTruthFile}}
                    .dump(2)
                    .c_str());
  } else {
    std::printf("capture written to %s (%zu sensors, seed %d); ground truth in %s/%s\n",
                out.c_str(), m.sensors.size(), seed, out.c_str(), kCaptureGroundTruthFile);
  }
  return cli::kExitOk;
}

}  // namespace linecal::tools
