// linecal eval calibrate: Monte Carlo evaluation of camera-to-car calibration over random
// cars on a station (docs/acceptance.md, "Solvers"; the table is in docs/solvers.md).
//
// Per car and camera: mounting angle and position errors uniform within ±1.5x the
// tolerance (so some cars are out of tolerance), a random aligner pose, the simulator's exact
// projections of every visible target feature (VisibleCameraFeatures) plus Gaussian corner
// noise; CalibrateCamera; the estimate against the truth, and the seed formulas (method (b)
// against method (a), the vertical board's roll against the truth and the pose). The
// detectors are not in this loop (their accuracy is measured by their own evaluations); the
// solver is.
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
#include "station/solvers/seed_formulas.h"
#include "tools/cli/command_line.h"
#include "tools/linecal/commands.h"
#include "tools/linecal/eval_harness.h"

namespace linecal::tools {
namespace {

constexpr char kCommand[] = "eval calibrate";
constexpr double kDegToRad = std::numbers::pi / 180.0;
constexpr double kRadToDeg = 180.0 / std::numbers::pi;
// Acceptance bars (docs/acceptance.md, "Solvers").
constexpr double kAngleP95BarDeg = 0.02;
constexpr double kPositionP95BarM = 0.010;
constexpr double kVanishingPointBarPx = 0.3;
constexpr double kRangingBarFraction = 0.005;
// The seed formulas (method (b)) against the extrinsic (method (a)): 0.5 px, 0.5%.
constexpr double kSeedVanishingPointBarPx = 0.5;
constexpr double kSeedRangingBarFraction = 0.005;
// Mounting errors within ±this x the tolerance: about a third of the cars out of tolerance.
constexpr double kErrorRangeOfTolerance = 1.5;
// Features closer than this to the image border are not used (a detector's window needs it).
constexpr double kFeatureMarginPx = 8.0;
// Ground distances of the ranging bar.
const double kRangingDistancesM[] = {5, 10, 20, 50};

struct CameraSamples {
  int cars = 0;
  std::map<std::string, int> reasons;  // verdict error reasons
  MountingSamples mounting;
  std::vector<double> vp_errors_px, ranging_errors;
  // Method (b) against method (a), and the vertical board's roll against the truth and the pose.
  std::vector<double> seed_vp_px, seed_ranging, toolbox_ranging;
  std::vector<double> line_roll_errors, line_roll_vs_pose;
  std::map<std::string, int>
      seed_refusals;  // reasons of method (b) where the camera saw the chessboard
};

void EvaluateCar(const StationLayout& station, const CarModel& car, std::mt19937_64& rng,
                 double noise_px, int frames, std::map<std::string, CameraSamples>* out) {
  std::normal_distribution<double> normal(0.0, 1.0);
  const AlignerMeasurement aligner = RandomAligner(rng);
  for (const SensorModel& s : car.sensors) {
    if (s.kind != SensorKind::kCamera || !s.intrinsics) continue;
    CameraSamples& samples = (*out)[s.name];
    ++samples.cars;
    const TrueMounting truth = RandomMounting(s, kErrorRangeOfTolerance, rng);
    const Rigid3d& T_car_camera = truth.T_car_sensor;
    const CameraModel camera = *CameraModel::Create(*s.intrinsics);
    const std::vector<RenderedFeature> visible = VisibleCameraFeatures(
        camera, aligner.T_station_car() * T_car_camera, station, {}, kFeatureMarginPx);
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
    if (r->verdict == Verdict::kError) ++samples.reasons[r->reason];
    samples.mounting.Add(r->mounting, truth, r->verdict);
    const MountingEstimate& m = r->mounting;
    if (r->vertical_roll.valid) {
      const double roll_true =
          MountingAngles(T_car_camera.RotationMatrix(), SensorBaseRotation(s.kind)).roll;
      samples.line_roll_errors.push_back(std::abs(r->vertical_roll.roll_rad - roll_true));
      samples.line_roll_vs_pose.push_back(std::abs(r->vertical_roll.roll_rad - m.angles.roll));
    }
    if (r->board_method.valid && r->vanishing_point_valid) {
      samples.seed_vp_px.push_back(r->vanishing_point_disagreement_px);
      for (double d : r->ground_disagreement) {
        if (std::isfinite(d)) samples.seed_ranging.push_back(d);
      }
      for (double d : r->toolbox_ground_disagreement) {
        if (std::isfinite(d)) samples.toolbox_ranging.push_back(d);
      }
    } else if (r->board_method.reason != "chessboard_not_seen") {
      ++samples.seed_refusals[r->board_method.reason];
    }
    // The vanishing point and the ground homography against the true extrinsic's.
    const Rigid3d T_camera_car = T_car_camera.Inverse();
    const Eigen::Matrix3d H_true = GroundHomography(*s.intrinsics, T_camera_car);
    // The vanishing point and ranging apply to cameras looking along the car.
    const int along = CarAxisAlong(T_camera_car);
    if (along == 0 || !r->vanishing_point_valid) continue;
    Eigen::Vector2d vp_true;
    CarAxisVanishingPoint(*s.intrinsics, T_camera_car, &vp_true);
    samples.vp_errors_px.push_back((r->vanishing_point_px - vp_true).norm());
    // Ranging: a ground point D ahead of the camera, imaged by the true homography, mapped
    // back to the ground by the calibrated one.
    for (double e : GroundDisagreement(H_true, r->ground_homography, T_car_camera.translation(),
                                       along, kRangingDistancesM)) {
      if (std::isfinite(e)) samples.ranging_errors.push_back(e);
    }
  }
}

// One camera's statistics against the bars: its JSON row and its table line in `report`.
// Returns whether the camera meets every bar.
bool ReportCamera(const std::string& name, const CameraSamples& c, EvalReport* report) {
  const MountingSummary summary = Summarise(c.mounting);
  const ErrorSigmaStats* stats = summary.stats;
  const double vp95 = Percentile(c.vp_errors_px, 0.95);
  const double range95 = Percentile(c.ranging_errors, 0.95);
  const double seed_vp95 = Percentile(c.seed_vp_px, 0.95);
  const double seed_range95 = Percentile(c.seed_ranging, 0.95);
  const double toolbox_range95 = Percentile(c.toolbox_ranging, 0.95);
  const double roll_lines95 = Percentile(c.line_roll_errors, 0.95);
  const double roll_lines_pose95 = Percentile(c.line_roll_vs_pose, 0.95);
  const bool seed_meets =
      seed_vp95 <= kSeedVanishingPointBarPx && seed_range95 <= kSeedRangingBarFraction;
  const double agreement = summary.agreement;
  const int solved = static_cast<int>(c.mounting.errors[0].size());
  const bool meets = solved == c.cars && MaxAngleP95(summary) <= kAngleP95BarDeg * kDegToRad &&
                     MaxPositionP95(summary) <= kPositionP95BarM && vp95 <= kVanishingPointBarPx &&
                     range95 <= kRangingBarFraction && SigmaMeetsBars(summary) &&
                     agreement == 1.0 && seed_meets;
  const std::string errors = ReasonsText(c.reasons);
  nlohmann::json row = {{"camera", name},
                        {"cars", c.cars},
                        {"solved", solved},
                        {"vanishing_point_p95_px", vp95},
                        {"ranging_p95_fraction", range95},
                        {"verdict_agreement", agreement},
                        {"verdicts_judged", c.mounting.verdicts_judged},
                        {"errors", c.reasons},
                        {"meets_bars", meets}};
  // Method (b) and the vertical board's roll, where the camera saw those boards.
  row["board_method_cars"] = c.seed_vp_px.size();
  row["board_method_refusals"] = c.seed_refusals;
  row["board_method_vanishing_point_p95_px"] =
      c.seed_vp_px.empty() ? nlohmann::json(nullptr) : nlohmann::json(seed_vp95);
  row["board_method_ranging_p95_fraction"] =
      c.seed_ranging.empty() ? nlohmann::json(nullptr) : nlohmann::json(seed_range95);
  row["board_method_toolbox_ranging_p95_fraction"] =
      c.toolbox_ranging.empty() ? nlohmann::json(nullptr) : nlohmann::json(toolbox_range95);
  row["board_method_meets_bars"] = seed_meets;
  row["vertical_roll_cars"] = c.line_roll_errors.size();
  row["vertical_roll_p95_abs_error_deg"] = c.line_roll_errors.empty()
                                               ? nlohmann::json(nullptr)
                                               : nlohmann::json(roll_lines95 * kRadToDeg);
  row["vertical_roll_p95_vs_pose_deg"] = c.line_roll_vs_pose.empty()
                                             ? nlohmann::json(nullptr)
                                             : nlohmann::json(roll_lines_pose95 * kRadToDeg);
  AddMountingColumns(summary, &row);
  report->AddRow(std::move(row));
  // Side cameras have no vanishing point or ranging along the car: "-".
  const std::string vp = c.vp_errors_px.empty() ? "-" : absl::StrFormat("%.3f", vp95);
  const std::string range = c.ranging_errors.empty() ? "-" : absl::StrFormat("%.3f", range95 * 100);
  // "-": the camera does not see the wide chessboard (method (b)) or the vertical board.
  const std::string seed = c.seed_vp_px.empty()
                               ? "-"
                               : absl::StrFormat("%.3f / %.3f / %.3f", seed_vp95,
                                                 seed_range95 * 100, toolbox_range95 * 100);
  const std::string roll =
      c.line_roll_errors.empty()
          ? "-"
          : absl::StrFormat("%.4f / %.4f", roll_lines95 * kRadToDeg, roll_lines_pose95 * kRadToDeg);
  report->Table(
      "%-16s %5d %6d | %8.4f %8.4f %8.4f  | %7.2f %7.2f %7.2f  | %7s %8s | %5.2f..%-5.2f "
      "%4.2f..%-4.2f | %6.1f%% | %-27s | %-15s | %s%s\n",
      name, c.cars, solved, stats[0].p95_abs_error * kRadToDeg, stats[1].p95_abs_error * kRadToDeg,
      stats[2].p95_abs_error * kRadToDeg, stats[3].p95_abs_error * 1e3,
      stats[4].p95_abs_error * 1e3, stats[5].p95_abs_error * 1e3, vp, range, summary.ratio_lo,
      summary.ratio_hi, summary.cover_lo, summary.cover_hi, agreement * 100, seed, roll,
      errors.empty() ? "-" : errors, meets ? "" : "  (misses a bar)");
  return meets;
}

}  // namespace

int RunEvalCalibrate(const Args& args) {
  cli::CommandLine cl(
      "linecal eval calibrate --station FILE --car FILE [--cars N] [--seed S] [--noise-px P] "
      "[--frames F] [--json]",
      "Monte Carlo evaluation of camera-to-car calibration: N cars with random mounting errors "
      "(uniform within 1.5x each tolerance) and aligner poses; every camera's visible target "
      "features (exact projections) plus Gaussian corner noise are solved, and the estimates "
      "compared with the truth. Prints per camera the 95th-percentile angle and position "
      "errors, vanishing point and ground ranging errors, the reported sigma against the spread "
      "(RMS error / RMS sigma) and the 95% coverage, the verdict agreement, and for cameras that "
      "see the wide chessboard method (b)'s vanishing point and ground disagreement from the "
      "extrinsic's (levelled, and the toolbox formula's, reported only), each against "
      "docs/acceptance.md's bar; and the roll from the vertical board against the truth and the "
      "pose. "
      "Exit 0 when every camera meets every bar, 1 otherwise.",
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
  if (!(*noise >= 0 && *noise <= 10))
    return cli::BadInput(kCommand, absl::StrCat("--noise-px: ", *noise, ": must be in [0, 10]"));

  std::mt19937_64 rng(static_cast<std::uint64_t>(in.seed));
  std::map<std::string, CameraSamples> samples;
  // The trials cannot fail: a camera that is not solved is a counted reason.
  (void)RunTrials(in.cars, 50, kCommand, [&](int) {
    EvaluateCar(in.station, in.car, rng, *noise, in.frames, &samples);
    return absl::OkStatus();
  });

  EvalReport report(cl);
  report.Table("%-16s %5s %6s | %-27s | %-24s | %7s %8s | %11s %9s | %7s | %-27s | %-15s | %s\n",
               "camera", "cars", "solved", "p95 |err| yaw/pitch/roll deg", "p95 |err| x/y/z mm",
               "vp px", "range %", "err/sigma", "cover95", "verdict", "(b)-(a) vp px/rng%/toolbox%",
               "roll lines deg", "errors");
  bool all_meet = true;
  for (const SensorModel& s : in.car.sensors) {
    if (samples.count(s.name)) all_meet &= ReportCamera(s.name, samples.at(s.name), &report);
  }
  report.Table(
      "bars: p95 angles <= %.2f deg, positions <= %.0f mm, vanishing point <= %.1f px, ranging <= "
      "%.1f%%, "
      "error/sigma %.1f..%.1f, coverage %.2f..%.2f, verdict agreement 100%%, method (b) vs (a) <= "
      "%.1f px / "
      "%.1f%%: %s\n",
      kAngleP95BarDeg, kPositionP95BarM * 1e3, kVanishingPointBarPx, kRangingBarFraction * 100,
      kSigmaRatioLow, kSigmaRatioHigh, kCoverageLow, kCoverageHigh, kSeedVanishingPointBarPx,
      kSeedRangingBarFraction * 100, all_meet ? "all met" : "NOT all met");
  return report.Finish(
      {{"cars", in.cars}, {"seed", in.seed}, {"noise_px", *noise}, {"frames", in.frames}},
      "cameras", all_meet);
}

}  // namespace linecal::tools
