// linecal eval calibrate: Monte Carlo evaluation of camera-to-car calibration over random
// cars on a station (acceptance.md, "Solvers"; the table is in docs/solvers.md).
//
// Per car and camera: mounting angle and position errors uniform within ±1.5x the
// tolerance (so some cars are out of tolerance), a random aligner pose, the simulator's exact
// projections of every visible target feature (VisibleCameraFeatures) plus Gaussian corner
// noise; CalibrateCamera; the estimate against the truth. The detectors are not in this loop
// (their accuracy is measured by their own evaluations); the solver is.
#include <cmath>
#include <cstdio>
#include <map>
#include <nlohmann/json.hpp>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "station/model/aligner.h"
#include "station/sim/camera_render.h"
#include "station/solvers/camera_calibration.h"
#include "tools/cli/command_line.h"
#include "tools/linecal/commands.h"
#include "tools/linecal/eval_stats.h"

namespace linecal::tools {
namespace {

constexpr char kCommand[] = "eval calibrate";
constexpr double kDegToRad = std::numbers::pi / 180.0;
constexpr double kRadToDeg = 180.0 / std::numbers::pi;
// Acceptance bars (acceptance.md, "Solvers").
constexpr double kAngleP95BarDeg = 0.02;
constexpr double kPositionP95BarM = 0.010;
constexpr double kVanishingPointBarPx = 0.3;
constexpr double kRangingBarFraction = 0.005;
constexpr double kSigmaRatioLow = 0.8, kSigmaRatioHigh = 1.2;
constexpr double kCoverageLow = 0.93, kCoverageHigh = 0.97;
// Mounting errors within ±this x the tolerance: about a third of the cars out of tolerance.
constexpr double kErrorRangeOfTolerance = 1.5;
// Features closer than this to the image border are not used (a detector's window needs it).
constexpr double kFeatureMarginPx = 8.0;
// Ground distances of the ranging bar.
const double kRangingDistancesM[] = {5, 10, 20, 50};
const char* kComponents[6] = {"yaw", "pitch", "roll", "x", "y", "z"};

struct CameraSamples {
  int cars = 0;
  std::map<std::string, int> reasons;  // verdict error reasons
  MountingSamples mounting;
  std::vector<double> vp_errors_px, ranging_errors;
};

Eigen::Matrix3d GroundHomography(const CameraIntrinsics& k, const Rigid3d& T_camera_car) {
  Eigen::Matrix3d K;
  K << k.fx, 0, k.cx, 0, k.fy, k.cy, 0, 0, 1;
  const Eigen::Matrix3d R = T_camera_car.RotationMatrix();
  Eigen::Matrix3d rt;
  rt << R.col(0), R.col(1), T_camera_car.translation();
  return K * rt;
}

void EvaluateCar(const StationLayout& station, const CarModel& car, std::mt19937_64& rng, double noise_px, int frames,
                 std::map<std::string, CameraSamples>* out) {
  std::normal_distribution<double> normal(0.0, 1.0);
  const AlignerMeasurement aligner = RandomAligner(rng);
  for (const SensorModel& s : car.sensors) {
    if (s.kind != SensorKind::kCamera || !s.intrinsics) continue;
    CameraSamples& samples = (*out)[s.name];
    ++samples.cars;
    const TrueMounting truth = RandomMounting(s, kErrorRangeOfTolerance, rng);
    const Rigid3d& T_car_camera = truth.T_car_sensor;
    const CameraModel camera = *CameraModel::Create(*s.intrinsics);
    const std::vector<RenderedFeature> visible =
        VisibleCameraFeatures(camera, aligner.T_station_car() * T_car_camera, station, {}, kFeatureMarginPx);
    std::vector<BoardObservation> observations;
    for (int frame = 0; frame < frames; ++frame) {
      const size_t first = observations.size();
      for (const RenderedFeature& f : visible) {
        if (std::find(s.targets.begin(), s.targets.end(), f.board_id) == s.targets.end()) continue;
        if (observations.size() == first || observations.back().board_id != f.board_id) {
          observations.push_back({f.board_id, {}});
        }
        DetectedFeature d;
        d.id = f.feature_id;
        d.p_board = station.FindBoard(f.board_id)->board.features()[f.feature_id].p_board;
        const double du = noise_px * normal(rng);
        const double dv = noise_px * normal(rng);
        d.uv_px = f.uv_px + Eigen::Vector2d(du, dv);
        observations.back().features.push_back(d);
      }
    }
    const absl::StatusOr<CameraCalibrationResult> r =
        CalibrateCamera(s, station, aligner.T_station_car(), observations);
    if (!r.ok() || !r->solved) {
      ++samples.reasons[r.ok() ? r->reason : "invalid_input"];
      continue;
    }
    if (r->verdict == SensorVerdict::kError) ++samples.reasons[r->reason];
    samples.mounting.Add(r->mounting, truth, r->verdict);
    // The vanishing point and the ground homography against the true extrinsic's.
    const Rigid3d T_camera_car = T_car_camera.Inverse();
    const Eigen::Matrix3d H_true = GroundHomography(*s.intrinsics, T_camera_car);
    // The vanishing point and ranging apply to cameras looking along the car.
    const int along = CarAxisAlong(T_camera_car);
    if (along == 0 || !r->vanishing_point_valid) continue;
    const Eigen::Vector3d axis_image = along * H_true.col(0);  // K (±r1): the image of ±x_car
    samples.vp_errors_px.push_back((r->vanishing_point_px - axis_image.hnormalized()).norm());
    // Ranging: a ground point D ahead of the camera, imaged by the true homography, mapped
    // back to the ground by the calibrated one.
    const Eigen::Matrix3d H_est_inv = r->ground_homography.inverse();
    const Eigen::Vector3d c = T_car_camera.translation();
    for (double d : kRangingDistancesM) {
      const Eigen::Vector3d ground(c.x() + along * d, c.y(), 1.0);
      if ((T_camera_car * Eigen::Vector3d(ground.x(), ground.y(), 0)).z() <= 0) continue;  // behind the camera
      const Eigen::Vector3d pixel = H_true * ground;
      const Eigen::Vector2d back = (H_est_inv * pixel).hnormalized();
      samples.ranging_errors.push_back((back - ground.head<2>()).norm() / d);
    }
  }
}

}  // namespace

int RunEvalCalibrate(const Args& args) {
  cli::CommandLine cl(
      "linecal eval calibrate --station FILE --car FILE [--cars N] [--seed S] [--noise-px P] [--frames F] [--json]",
      "Monte Carlo evaluation of camera-to-car calibration: N cars with random mounting errors "
      "(uniform within 1.5x each tolerance) and aligner poses; every camera's visible target "
      "features (exact projections) plus Gaussian corner noise are solved, and the estimates "
      "compared with the truth. Prints per camera the 95th-percentile angle and position "
      "errors, vanishing point and ground ranging errors, the reported sigma against the spread "
      "(RMS error / RMS sigma) and the 95% coverage, and the verdict agreement, each against "
      "acceptance.md's bar. Exit 0 when every camera meets every bar, 1 otherwise.",
      {{"station", "FILE", "station layout", true},
       {"car", "FILE", "car model", true},
       {"cars", "N", "number of random cars (default 200)"},
       {"seed", "S", "random seed (default 1)"},
       {"noise-px", "P", "corner noise sigma, pixels (default 0.2)"},
       {"frames", "F", "frames per camera, each with fresh noise (default 3)"},
       {"json", "", "print one JSON object"}});
  if (const std::optional<int> exit = cli::ParseOrExit(cl, kCommand, args)) return *exit;
  // A station grabs several frames per camera (the daemon's frames_per_sensor); each frame's
  // corners carry fresh noise here, which real detectors' small fixed biases do not.
  absl::StatusOr<EvalInputs> inputs = ReadEvalInputs(cl, 3);
  if (!inputs.ok()) return cli::BadInput(kCommand, std::string(inputs.status().message()));
  const EvalInputs& in = *inputs;
  const absl::StatusOr<double> noise = cl.GetDouble("noise-px", 0.2);
  if (!noise.ok()) return cli::BadInput(kCommand, std::string(noise.status().message()));
  if (!(*noise >= 0 && *noise <= 10)) return cli::BadInput(kCommand, absl::StrCat("--noise-px: ", *noise, ": must be in [0, 10]"));

  std::mt19937_64 rng(static_cast<std::uint64_t>(in.seed));
  std::map<std::string, CameraSamples> samples;
  for (int i = 0; i < in.cars; ++i) {
    EvaluateCar(in.station, in.car, rng, *noise, in.frames, &samples);
    if ((i + 1) % 50 == 0) std::fprintf(stderr, "eval calibrate: %d / %d cars\n", i + 1, in.cars);
  }

  bool all_meet = true;
  nlohmann::json rows = nlohmann::json::array();
  if (!cl.Has("json")) {
    std::printf("%-16s %5s %6s | %-27s | %-24s | %7s %8s | %11s %9s | %7s | %s\n", "camera", "cars", "solved",
                "p95 |err| yaw/pitch/roll deg", "p95 |err| x/y/z mm", "vp px", "range %", "err/sigma", "cover95",
                "verdict", "errors");
  }
  for (const SensorModel& s : in.car.sensors) {
    if (!samples.count(s.name)) continue;
    const CameraSamples& c = samples[s.name];
    const MountingSummary summary = Summarise(c.mounting);
    const ErrorSigmaStats* stats = summary.stats;
    const double ratio_lo = summary.ratio_lo, ratio_hi = summary.ratio_hi;
    const double cover_lo = summary.cover_lo, cover_hi = summary.cover_hi;
    const double vp95 = Percentile(c.vp_errors_px, 0.95);
    const double range95 = Percentile(c.ranging_errors, 0.95);
    const double agreement = summary.agreement;
    const int solved = static_cast<int>(c.mounting.errors[0].size());
    const bool meets = solved == c.cars &&
                       std::max({stats[0].p95_abs_error, stats[1].p95_abs_error, stats[2].p95_abs_error}) <=
                           kAngleP95BarDeg * kDegToRad &&
                       std::max({stats[3].p95_abs_error, stats[4].p95_abs_error, stats[5].p95_abs_error}) <=
                           kPositionP95BarM &&
                       vp95 <= kVanishingPointBarPx && range95 <= kRangingBarFraction && ratio_lo >= kSigmaRatioLow &&
                       ratio_hi <= kSigmaRatioHigh && cover_lo >= kCoverageLow && cover_hi <= kCoverageHigh &&
                       agreement == 1.0;
    all_meet &= meets;
    std::string errors;
    for (const auto& [reason, count] : c.reasons) absl::StrAppend(&errors, errors.empty() ? "" : ", ", reason, " ", count);
    nlohmann::json row = {{"camera", s.name},           {"cars", c.cars},
                          {"solved", solved},           {"vanishing_point_p95_px", vp95},
                          {"ranging_p95_fraction", range95}, {"verdict_agreement", agreement},
                          {"verdicts_judged", c.mounting.verdicts_judged}, {"errors", c.reasons},
                          {"meets_bars", meets}};
    for (int i = 0; i < 6; ++i) {
      const double scale = i < 3 ? kRadToDeg : 1e3;
      const std::string unit = i < 3 ? "_deg" : "_mm";
      row[absl::StrCat(kComponents[i], "_p95_abs_error", unit)] = stats[i].p95_abs_error * scale;
      row[absl::StrCat(kComponents[i], "_error_over_sigma")] = stats[i].error_over_sigma;
      row[absl::StrCat(kComponents[i], "_coverage95")] = stats[i].coverage95;
    }
    rows.push_back(row);
    if (!cl.Has("json")) {
      // Side cameras have no vanishing point or ranging along the car: "-".
      const std::string vp = c.vp_errors_px.empty() ? "-" : absl::StrFormat("%.3f", vp95);
      const std::string range = c.ranging_errors.empty() ? "-" : absl::StrFormat("%.3f", range95 * 100);
      std::printf("%-16s %5d %6d | %8.4f %8.4f %8.4f  | %7.2f %7.2f %7.2f  | %7s %8s | %5.2f..%-5.2f %4.2f..%-4.2f | %6.1f%% | %s%s\n",
                  s.name.c_str(), c.cars, solved, stats[0].p95_abs_error * kRadToDeg,
                  stats[1].p95_abs_error * kRadToDeg, stats[2].p95_abs_error * kRadToDeg,
                  stats[3].p95_abs_error * 1e3, stats[4].p95_abs_error * 1e3, stats[5].p95_abs_error * 1e3, vp.c_str(),
                  range.c_str(), ratio_lo, ratio_hi, cover_lo, cover_hi, agreement * 100,
                  errors.empty() ? "-" : errors.c_str(), meets ? "" : "  (misses a bar)");
    }
  }
  if (cl.Has("json")) {
    std::printf("%s\n", nlohmann::json({{"cars", in.cars}, {"seed", in.seed}, {"noise_px", *noise}, {"frames", in.frames}, {"cameras", rows},
                                        {"meets_bars", all_meet}})
                            .dump(2)
                            .c_str());
  } else {
    std::printf("bars: p95 angles <= %.2f deg, positions <= %.0f mm, vanishing point <= %.1f px, ranging <= %.1f%%, "
                "error/sigma %.1f..%.1f, coverage %.2f..%.2f, verdict agreement 100%%: %s\n",
                kAngleP95BarDeg, kPositionP95BarM * 1e3, kVanishingPointBarPx, kRangingBarFraction * 100,
                kSigmaRatioLow, kSigmaRatioHigh, kCoverageLow, kCoverageHigh, all_meet ? "all met" : "NOT all met");
  }
  return all_meet ? cli::kExitOk : cli::kExitNegative;
}

}  // namespace linecal::tools
