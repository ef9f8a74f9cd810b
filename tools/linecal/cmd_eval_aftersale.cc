// linecal eval aftersale: Monte Carlo accuracy of the lane-line calibration (docs/aftersale.md).
#include <cmath>
#include <cstdio>
#include <nlohmann/json.hpp>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "station/sim/lane_scene.h"
#include "station/solvers/lane_calibration.h"
#include "tools/cli/command_line.h"
#include "tools/linecal/car_camera.h"
#include "tools/linecal/commands.h"
#include "tools/linecal/eval_harness.h"

namespace linecal::tools {
namespace {

constexpr char kCommand[] = "eval aftersale";
constexpr double kDeg = std::numbers::pi / 180.0;

// The list given with --flag, else `fallback`.
absl::StatusOr<std::vector<double>> NumberList(const cli::CommandLine& cl, const std::string& flag,
                                               const std::vector<double>& fallback) {
  if (!cl.Has(flag)) return fallback;
  return cli::ParseNumberList(cl.Get(flag), "--" + flag);
}

struct Row {
  double noise_px = 0;
  int trials = 0, errors = 0;
  std::vector<double> vp, yaw, pitch, roll, ranging, marked;
};

// The flags of the evaluation besides --car and --camera, checked; the error names the flag.
struct AftersaleEvalFlags {
  int trials = 0, seed = 0;
  double perturb_deg = 0, roll_line_m = 0, marked_m = 0;
  std::vector<double> noises_px, points_m, ranging_m;
};
absl::StatusOr<AftersaleEvalFlags> ReadAftersaleEvalFlags(const cli::CommandLine& cl) {
  absl::StatusOr<int> trials = cl.GetInt("trials", 1000);
  absl::StatusOr<int> seed = cl.GetInt("seed", 1);
  absl::StatusOr<double> perturb = cl.GetDouble("perturb-deg", 2.0);
  absl::StatusOr<double> roll_line = cl.GetDouble("roll-line-m", 8.0);
  absl::StatusOr<double> marked = cl.GetDouble("marked-point-m", 15.0);
  absl::StatusOr<std::vector<double>> noises = NumberList(cl, "noise-px", {0.1, 0.3, 0.5, 1.0});
  absl::StatusOr<std::vector<double>> points = NumberList(cl, "points-m", {5, 10, 20, 30});
  absl::StatusOr<std::vector<double>> ranging = NumberList(cl, "ranging-m", {5, 10, 20, 30});
  for (const absl::Status& s :
       {trials.status(), seed.status(), perturb.status(), roll_line.status(), marked.status(),
        noises.status(), points.status(), ranging.status()}) {
    if (!s.ok()) return s;
  }
  if (*trials < 1 || *trials > 1000000)
    return absl::InvalidArgumentError(
        absl::StrCat("--trials: must be in 1..1000000, got ", *trials));
  if (*seed < 0)
    return absl::InvalidArgumentError(absl::StrCat("--seed: must be >= 0, got ", *seed));
  if (!(*perturb >= 0 && *perturb <= 20))
    return absl::InvalidArgumentError(
        absl::StrCat("--perturb-deg: must be in [0, 20], got ", *perturb));
  return AftersaleEvalFlags{*trials,
                            *seed,
                            *perturb,
                            *roll_line,
                            *marked,
                            *std::move(noises),
                            *std::move(points),
                            *std::move(ranging)};
}

// The camera under test at its nominal mounting.
struct CameraUnderTest {
  const SensorModel* sensor;
  CameraModel camera;
  Eigen::Matrix3d r_base;
  YawPitchRoll nominal;
  Eigen::Vector3d xyz;
  bool backward;  // looks against the car's x axis
};

// One trial: a random mounting within ±flags.perturb_deg of the nominal one, the lane scene's
// points with options `o`, calibrated, and the errors against the truth added to `row` (or
// counted as refused). Draws from `rng`; the error is the scene renderer's.
absl::Status EvaluateTrial(const CameraUnderTest& c, const AftersaleEvalFlags& flags,
                           const LaneSceneOptions& o, std::mt19937_64& rng, Row* row) {
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  const double along = c.backward ? -1 : 1;
  const double perturb = flags.perturb_deg;
  const double dy = unit(rng), dp = unit(rng), dr = unit(rng);
  const YawPitchRoll a{c.nominal.yaw + perturb * kDeg * dy, c.nominal.pitch + perturb * kDeg * dp,
                       c.nominal.roll + perturb * kDeg * dr};
  const Rigid3d T_car_camera(MountingRotation(a, c.r_base), c.xyz);
  ++row->trials;
  absl::StatusOr<LaneScene> scene = RenderLaneScene(c.camera, T_car_camera, o, rng());
  if (!scene.ok()) return scene.status();
  LaneCalibrationInput in;
  in.intrinsics = *c.sensor->intrinsics;
  in.lanes_px = scene->lanes_px;
  if (scene->has_roll_line) in.roll_line_px = scene->roll_line_px;
  in.looking_backward = c.backward;
  in.camera_height_m = c.xyz.z();
  in.longitudinal_offset_m = c.xyz.x();
  in.lateral_offset_m = c.xyz.y();
  in.marked_point = LaneMarkedPoint{scene->marked_point_px, flags.marked_m};
  absl::StatusOr<LaneCalibrationResult> r = CalibrateFromLanes(in);
  // Noise can push a point past the horizon or make lines parallel: counted, not judged.
  if (!r.ok()) {
    ++row->errors;
    return absl::OkStatus();
  }
  row->vp.push_back((r->vanishing_point_px - scene->vanishing_point_px).norm());
  row->yaw.push_back(
      std::abs(std::remainder(r->angles.yaw - scene->angles.yaw, 2 * std::numbers::pi)) / kDeg);
  row->pitch.push_back(std::abs(r->angles.pitch - scene->angles.pitch) / kDeg);
  row->roll.push_back(std::abs(r->angles.roll - scene->angles.roll) / kDeg);
  double worst = 0;
  for (double d : flags.ranging_m) {
    for (double y : {-1.75, 0.0, 1.75}) {
      const double e =
          RelativeRangingError(c.camera, T_car_camera, r->T_car_camera, {c.xyz.x() + along * d, y});
      if (std::isfinite(e)) worst = std::max(worst, e);
    }
  }
  row->ranging.push_back(100 * worst);
  row->marked.push_back(std::abs(r->distance_check->error_percent));
  return absl::OkStatus();
}

}  // namespace

int RunEvalAftersale(const Args& args) {
  cli::CommandLine cl(
      "linecal eval aftersale --car FILE --camera NAME [--trials N] [--noise-px S,S,...] [options]",
      "Monte Carlo evaluation of the after-sale lane calibration: random mountings (nominal +- "
      "--perturb-deg on "
      "every angle), the lane scene's exact points plus Gaussian noise, calibrated; p95 errors of "
      "the vanishing "
      "point, yaw, pitch, roll, the ranging over ground points 5-30 m ahead across the lane, and "
      "the distance "
      "check at the marked point, per noise level.",
      {{"car", "FILE", "car model", true},
       {"camera", "NAME", "the camera of the car model", true},
       {"trials", "N", "mountings per noise level (default 1000)"},
       {"noise-px", "S,S,...", "point noise levels, pixels (default 0.1,0.3,0.5,1)"},
       {"perturb-deg", "A", "mounting error bound per angle, degrees (default 2)"},
       {"points-m", "D,D[,...]", "distances of the points on each lane line (default 5,10,20,30)"},
       {"roll-line-m", "D", "the roll line's distance, 0 = none: roll assumed 0 (default 8)"},
       {"ranging-m", "D,D[,...]", "ground distances of the ranging error (default 5,10,20,30)"},
       {"marked-point-m", "D", "the marked point's distance (default 15)"},
       {"seed", "N", "random seed (default 1)"},
       {"json", "", "print the result as JSON"}});
  if (auto code = cli::ParseOrExit(cl, kCommand, args)) return *code;
  absl::StatusOr<SensorModel> camera_sensor = ReadCarCamera(cl.Get("car"), cl.Get("camera"));
  if (!camera_sensor.ok())
    return cli::BadInput(kCommand, std::string(camera_sensor.status().message()));
  const SensorModel* sensor = &*camera_sensor;
  const absl::StatusOr<AftersaleEvalFlags> flags = ReadAftersaleEvalFlags(cl);
  if (!flags.ok()) return cli::BadInput(kCommand, std::string(flags.status().message()));

  const Eigen::Matrix3d r_base = CameraBaseRotation();
  const YawPitchRoll nominal =
      MountingAngles(sensor->T_car_sensor_nominal.RotationMatrix(), r_base);
  const CameraUnderTest c{
      sensor,  *CameraModel::Create(*sensor->intrinsics),  r_base,
      nominal, sensor->T_car_sensor_nominal.translation(), std::cos(nominal.yaw) < 0};
  std::mt19937_64 rng(static_cast<std::uint64_t>(flags->seed));
  std::vector<Row> rows;
  for (double noise : flags->noises_px) {
    LaneSceneOptions o;
    o.render_image = false;
    o.point_distances_m = flags->points_m;
    o.roll_line_distance_m = flags->roll_line_m;
    o.marked_point_distance_m = flags->marked_m;
    o.point_noise_px = noise;
    if (absl::Status s = o.Validate(); !s.ok())
      return cli::BadInput(kCommand, std::string(s.message()));
    Row row;
    row.noise_px = noise;
    for (int t = 0; t < flags->trials; ++t) {
      if (absl::Status s = EvaluateTrial(c, *flags, o, rng, &row); !s.ok()) {
        return cli::BadInput(kCommand, std::string(s.message()));
      }
    }
    rows.push_back(row);
  }

  EvalReport report(cl);
  report.Table(
      "| point noise, px | p95 vanishing point, px | p95 yaw / pitch / roll, deg | p95 ranging "
      "5-30 m, %% | "
      "p95 marked point, %% | refused |\n| --- | --- | --- | --- | --- | --- |\n");
  for (const Row& r : rows) {
    const double vp = Percentile(r.vp, 0.95), yaw = Percentile(r.yaw, 0.95),
                 pitch = Percentile(r.pitch, 0.95), roll = Percentile(r.roll, 0.95),
                 rg = Percentile(r.ranging, 0.95), mk = Percentile(r.marked, 0.95);
    report.AddRow({{"noise_px", r.noise_px},
                   {"trials", r.trials},
                   {"refused", r.errors},
                   {"vanishing_point_p95_px", vp},
                   {"yaw_p95_deg", yaw},
                   {"pitch_p95_deg", pitch},
                   {"roll_p95_deg", roll},
                   {"ranging_p95_percent", rg},
                   {"marked_point_p95_percent", mk}});
    report.Table("| %.2f | %.3f | %.4f / %.4f / %.4f | %.3f | %.3f | %d of %d |\n", r.noise_px, vp,
                 yaw, pitch, roll, rg, mk, r.errors, r.trials);
  }
  // No bars here (docs/aftersale.md reads the table): the JSON is the rows alone, exit 0.
  return report.Finish(nullptr, "", true);
}

}  // namespace linecal::tools
