#include "station/radar/radar_calibration.h"

#include <algorithm>
#include <cmath>
#include <numbers>

#include "absl/strings/str_cat.h"

namespace linecal {
namespace {

// Gauss-Newton in one unknown converges quadratically; the step test is far below any
// meaningful yaw (1e-12 rad) and the iteration cap is a guard, never reached in practice.
constexpr int kMaxIterations = 20;
constexpr double kStepToleranceRad = 1e-12;

// M = Rx(roll)ᵀ · Ry(pitch)ᵀ: radar frame from the frame turned by yaw only.
Eigen::Matrix3d PitchRollTransposed(const YawPitchRoll& angles) {
  return RotationFromYawPitchRoll({0, angles.pitch, angles.roll}).transpose();
}

// q = Rz(yaw)ᵀ (p_car − t): the point in the frame turned by yaw only.
Eigen::Vector3d YawFramePoint(double yaw, const Eigen::Vector3d& t, const Eigen::Vector3d& p_car) {
  return Eigen::AngleAxisd(-yaw, Eigen::Vector3d::UnitZ()) * (p_car - t);
}

// Lateral shifts of the position grid over which the joint rounding error is averaged. The
// error of one reflector is a sawtooth of its place in the cell; 16 points resolve the
// weighted sum of a few of them to well under 1% of its RMS.
constexpr int kGridShifts = 16;

// The two-sided 95% point of the standard normal distribution.
constexpr double kZ95 = 1.959963984540054;

// The half-width h of the interval that holds 95% of b + n, b drawn evenly from `offsets` and
// n ~ N(0, σ²): mean over b of P(|b + n| ≤ h) = 0.95, by bisection (the share grows with h).
// A grid error dominated by a few reflectors is close to uniform, whose 95% interval is
// 1.65σ wide, not 1.96σ.
double HalfWidth95(std::span<const double> offsets, double sigma) {
  double widest = 0;
  for (double b : offsets) widest = std::max(widest, std::abs(b));
  const auto share = [&](double h) {
    double p = 0;
    for (double b : offsets) {
      p += 0.5 * (std::erfc((-h - b) / (sigma * std::numbers::sqrt2)) -
                  std::erfc((h - b) / (sigma * std::numbers::sqrt2)));
    }
    return p / static_cast<double>(offsets.size());
  };
  double lo = 0, hi = widest + kZ95 * sigma;  // share(hi) ≥ 0.95
  for (int i = 0; i < 60; ++i) {
    const double mid = 0.5 * (lo + hi);
    (share(mid) < 0.95 ? lo : hi) = mid;
  }
  return hi;
}

// E[round(v + n)] − v for n ~ N(0, r²), v and r in steps: the error left in the mean of many
// readings of v quantised to whole steps, once noise of r steps dithers the rounding. The sum
// runs over the steps within 8r of v (the rest has probability < 1e-15).
double MeanRoundingError(double v, double r) {
  const double f = v - std::round(v);  // the error is periodic in v: take v within ½ step of 0
  if (r < 1e-9) return -f;
  const double reach = std::ceil(8 * r) + 1;
  const double scale = 1 / (r * std::numbers::sqrt2);
  double mean = 0;
  for (double m = -reach; m <= reach; ++m) {
    // P(round(f + n) = m) = Φ((m + ½ − f) / r) − Φ((m − ½ − f) / r), Φ(z) = erfc(−z/√2) / 2.
    mean += m * 0.5 * (std::erfc(-(m + 0.5 - f) * scale) - std::erfc(-(m - 0.5 - f) * scale));
  }
  return mean - f;
}

}  // namespace

absl::Status RadarCalibrationOptions::Validate() const {
  if (min_reflectors < 1) {
    return absl::InvalidArgumentError(
        absl::StrCat("min_reflectors = ", min_reflectors, ": must be >= 1"));
  }
  if (!(max_sigma_fraction_of_tolerance > 0 && std::isfinite(max_sigma_fraction_of_tolerance))) {
    return absl::InvalidArgumentError(
        absl::StrCat("max_sigma_fraction_of_tolerance = ", max_sigma_fraction_of_tolerance,
                     ": must be finite and > 0"));
  }
  return absl::OkStatus();
}

const char* RadarVerdictName(RadarVerdict verdict) {
  switch (verdict) {
    case RadarVerdict::kPass:
      return "pass";
    case RadarVerdict::kFail:
      return "fail";
    case RadarVerdict::kError:
      return "error";
  }
  return "unknown";
}

double PredictedAzimuth(const YawPitchRoll& angles, const Eigen::Vector3d& t_car_radar,
                        const Eigen::Vector3d& p_car) {
  const Eigen::Vector3d p =
      PitchRollTransposed(angles) * YawFramePoint(angles.yaw, t_car_radar, p_car);
  return std::atan2(p.y(), p.x());
}

double PredictedAzimuthYawDerivative(const YawPitchRoll& angles, const Eigen::Vector3d& t_car_radar,
                                     const Eigen::Vector3d& p_car) {
  const Eigen::Matrix3d m = PitchRollTransposed(angles);
  const Eigen::Vector3d q = YawFramePoint(angles.yaw, t_car_radar, p_car);
  // d Rz(−yaw)/d yaw · d = −e_z × q = (q_y, −q_x, 0).
  const Eigen::Vector3d p = m * q;
  const Eigen::Vector3d dp = m * Eigen::Vector3d(q.y(), -q.x(), 0);
  // d atan2(y, x) = (x dy − y dx) / (x² + y²).
  return (p.x() * dp.y() - p.y() * dp.x()) / (p.x() * p.x() + p.y() * p.y());
}

RadarCalibrationResult CalibrateRadarYaw(const SensorModel& sensor,
                                         std::span<const ExpectedReflector> expected,
                                         const ReflectorAssociation& association,
                                         const RadarCalibrationOptions& options) {
  RadarCalibrationResult out;
  const Eigen::Matrix3d r_base = SensorBaseRotation(SensorKind::kRadar);
  const YawPitchRoll nominal = MountingAngles(sensor.T_car_sensor_nominal.RotationMatrix(), r_base);
  const Eigen::Vector3d t = sensor.T_car_sensor_nominal.translation();
  out.nominal_yaw_rad = nominal.yaw;
  out.pitch_rad = nominal.pitch;
  out.roll_rad = nominal.roll;
  out.yaw_tolerance_rad = sensor.tolerance.yaw_rad;
  out.yaw_rad = nominal.yaw;
  out.T_car_radar = sensor.T_car_sensor_nominal;

  struct Used {
    const ExpectedReflector* expected;
    const ReflectorObservation* observed;
  };
  std::vector<Used> used;
  const size_t n = std::min(expected.size(), association.reflectors.size());
  for (size_t i = 0; i < n; ++i) {
    if (association.reflectors[i].status == ReflectorStatus::kFound &&
        association.reflectors[i].azimuth_se_rad > 0) {
      used.push_back({&expected[i], &association.reflectors[i]});
    }
  }
  out.reflectors_used = static_cast<int>(used.size());
  if (out.reflectors_used < options.min_reflectors || used.empty()) {
    out.verdict = RadarVerdict::kError;
    out.reason = "too_few_reflectors";
    return out;
  }

  // Weights from each reflector's error taken alone. Not from the scatter without the grid's
  // part: the grid makes it uneven (a reflector on a cell edge flips between two cells, one in
  // the middle never moves), and uneven weights would undo the cancellation of the grid's
  // errors between reflectors that a layout can provide. The σ below propagates each part of
  // the error through these weights.
  const auto weight = [](const Used& u) {
    return 1 / (u.observed->azimuth_se_rad * u.observed->azimuth_se_rad);
  };
  YawPitchRoll angles = nominal;
  double information = 0;
  for (int it = 0; it < kMaxIterations; ++it) {
    double jtj = 0, jtr = 0;
    for (const Used& u : used) {
      const double w = weight(u);
      const double r =
          std::remainder(u.observed->azimuth_rad - PredictedAzimuth(angles, t, u.expected->p_car),
                         2 * std::numbers::pi);
      const double j = PredictedAzimuthYawDerivative(angles, t, u.expected->p_car);
      jtj += w * j * j;
      jtr += w * j * r;
    }
    information = jtj;
    const double step = jtr / jtj;
    angles.yaw += step;
    if (std::abs(step) < kStepToleranceRad) break;
  }

  out.yaw_rad = angles.yaw;
  // How much the yaw moves per radian of each reflector's azimuth error: w ∂azimuth/∂yaw /
  // information, the Gauss-Newton step's gain.
  std::vector<double> gain;
  for (const Used& u : used) {
    gain.push_back(weight(u) * PredictedAzimuthYawDerivative(angles, t, u.expected->p_car) /
                   information);
  }
  // Σ gain² se², se without the position grid's part; equals 1 / √information when the grid
  // has none.
  double measurement_variance = 0;
  for (std::size_t i = 0; i < used.size(); ++i) {
    const double se = used[i].observed->azimuth_se_without_position_steps_rad;
    measurement_variance += gain[i] * gain[i] * se * se;
  }
  out.yaw_sigma_measurement_rad = std::sqrt(measurement_variance);
  // The yaw shift that pitch and roll off nominal by (dp, dr) cause: one Gauss-Newton step
  // from the solution towards azimuths predicted with them (the shift is far below a degree,
  // where one step is exact to well below the noise). Its mean square over dp, dr uniform in
  // ±tolerance uses the 3-point Gauss-Legendre rule per axis (exact for the quartic terms).
  constexpr double kNodes[3] = {-0.7745966692414834, 0.0, 0.7745966692414834};  // ±√(3/5)
  constexpr double kWeights[3] = {5.0 / 18, 8.0 / 18, 5.0 / 18};  // Legendre weights / 2
  double mean_square_shift = 0;
  for (int a = 0; a < 3; ++a) {
    for (int b = 0; b < 3; ++b) {
      YawPitchRoll tilted = angles;
      tilted.pitch += kNodes[a] * sensor.tolerance.pitch_rad;
      tilted.roll += kNodes[b] * sensor.tolerance.roll_rad;
      double jtr = 0;
      for (const Used& u : used) {
        const double w = weight(u);
        const double shift = std::remainder(PredictedAzimuth(tilted, t, u.expected->p_car) -
                                                PredictedAzimuth(angles, t, u.expected->p_car),
                                            2 * std::numbers::pi);
        jtr += w * PredictedAzimuthYawDerivative(angles, t, u.expected->p_car) * shift;
      }
      const double yaw_shift = jtr / information;
      mean_square_shift += kWeights[a] * kWeights[b] * yaw_shift * yaw_shift;
    }
  }
  out.yaw_sigma_pitch_roll_rad = std::sqrt(mean_square_shift);

  // The position grid (ARS408 clusters: 0.2 m in x and y). The noise hardly dithers it across
  // the line of sight (0.1° is 0.017 m at 10 m), so each reflector's mean azimuth keeps an
  // error fixed by where the reflector sits in its cell, and averaging cycles does not remove
  // it. These errors are not independent between reflectors: where they sit relative to each
  // other is known (surveyed layout, estimated yaw), and a row laid out at different places in
  // the cell cancels them, a row at one place adds them up. Across the line of sight, where
  // the whole set sits in the grid is not known beforehand: the yaw being measured moves it
  // (0.17 m per degree at 10 m, a cell within the tolerance). Along it, the reflectors ahead
  // stay where the layout and the mounting put them, which the calibration takes as nominal.
  // So the yaw error the reflectors cause together (one Gauss-Newton step as above) is
  // averaged in square over lateral shifts of the set across a whole cell, at the x the
  // estimate gives. (Averaging over x too overstated the σ by 10% on the reference station,
  // whose row stands at one x: 97% coverage over 3 x 1000 cars.)
  const double step = association.resolution.position_step_m;
  std::vector<double> grid_errors;  // the yaw error at each lateral shift of the grid
  if (step > 0) {
    struct Lever {
      Eigen::Vector2d p;          // radar frame, metres
      Eigen::Vector2d noise;      // per-detection σ along x and y, in steps
      Eigen::Vector2d d_azimuth;  // ∂azimuth/∂(x, y) times the reflector's gain
    };
    std::vector<Lever> levers;
    const Eigen::Matrix3d m = PitchRollTransposed(angles);
    for (std::size_t i = 0; i < used.size(); ++i) {
      const Eigen::Vector3d p = m * YawFramePoint(angles.yaw, t, used[i].expected->p_car);
      const double r2 = p.head<2>().squaredNorm();
      const double c = p.x() / std::sqrt(r2), s = p.y() / std::sqrt(r2);
      // Polar noise in Cartesian axes: range noise along the line of sight, azimuth noise
      // across it.
      const double along = association.detection_range_sigma_m;
      const double across = association.detection_azimuth_sigma_rad * std::sqrt(r2);
      levers.push_back(
          {p.head<2>(),
           Eigen::Vector2d(std::hypot(along * c, across * s), std::hypot(along * s, across * c)) /
               step,
           gain[i] * Eigen::Vector2d(-p.y(), p.x()) / r2});
    }
    double mean_square = 0;
    for (int i = 0; i < kGridShifts; ++i) {
      const double shift = (i + 0.5) / kGridShifts;
      double yaw_error = 0;
      for (const Lever& l : levers) {
        const double vx = (l.p.x() - association.resolution.position_x_origin_m) / step;
        const double vy = l.p.y() / step + shift;
        yaw_error += step * (l.d_azimuth.x() * MeanRoundingError(vx, l.noise.x()) +
                             l.d_azimuth.y() * MeanRoundingError(vy, l.noise.y()));
      }
      grid_errors.push_back(yaw_error);
      mean_square += yaw_error * yaw_error;
    }
    out.yaw_sigma_position_steps_rad = std::sqrt(mean_square / kGridShifts);
  }
  const double gaussian_sigma =
      std::hypot(out.yaw_sigma_measurement_rad, out.yaw_sigma_pitch_roll_rad);
  out.yaw_sigma_rad = std::hypot(gaussian_sigma, out.yaw_sigma_position_steps_rad);
  out.yaw_ci95_rad =
      grid_errors.empty() ? kZ95 * out.yaw_sigma_rad : HalfWidth95(grid_errors, gaussian_sigma);
  out.yaw_deviation_rad = std::remainder(angles.yaw - nominal.yaw, 2 * std::numbers::pi);
  out.T_car_radar = Rigid3d(MountingRotation(angles, r_base), t);
  out.dof = out.reflectors_used - 1;
  for (const Used& u : used) {
    RadarReflectorResidual res;
    res.reflector_id = u.observed->reflector_id;
    res.azimuth_measured_rad = u.observed->azimuth_rad;
    res.azimuth_predicted_rad = PredictedAzimuth(angles, t, u.expected->p_car);
    res.azimuth_se_rad = u.observed->azimuth_se_rad;
    res.residual_rad =
        std::remainder(res.azimuth_measured_rad - res.azimuth_predicted_rad, 2 * std::numbers::pi);
    out.chi2 += (res.residual_rad / res.azimuth_se_rad) * (res.residual_rad / res.azimuth_se_rad);
    out.residuals.push_back(res);
  }

  if (out.yaw_sigma_rad > options.max_sigma_fraction_of_tolerance * sensor.tolerance.yaw_rad) {
    out.verdict = RadarVerdict::kError;
    out.reason = "uncertainty_too_high";
  } else if (std::abs(out.yaw_deviation_rad) > sensor.tolerance.yaw_rad) {
    out.verdict = RadarVerdict::kFail;
    out.reason = "yaw_out_of_tolerance";
  } else {
    out.verdict = RadarVerdict::kPass;
    out.reason = "";
  }
  return out;
}

std::vector<RadarCycle> CalibrationCycles(std::span<const RadarCycle> all,
                                          const SensorModel& sensor) {
  std::vector<RadarCycle> out;
  const bool esr = sensor.model == "esr";
  for (const RadarCycle& c : all) {
    const bool wanted =
        esr ? c.kind == RadarDetectionKind::kTrack
            : c.kind == RadarDetectionKind::kCluster && c.sensor_id == sensor.radar_sensor_id;
    if (wanted) out.push_back(c);
  }
  return out;
}

absl::StatusOr<RadarCalibrationRun> CalibrateRadar(const SensorModel& sensor,
                                                   const StationLayout& layout,
                                                   const Rigid3d& T_station_car,
                                                   std::span<const RadarCycle> cycles,
                                                   const RadarCalibrationOptions& options) {
  if (absl::Status s = options.Validate(); !s.ok()) return s;
  absl::StatusOr<std::vector<ExpectedReflector>> expected =
      ExpectedReflectors(sensor, layout, T_station_car);
  if (!expected.ok()) return expected.status();
  absl::StatusOr<ReflectorAssociationOptions> association_options =
      ReflectorAssociationOptions::ForSensor(sensor);
  if (!association_options.ok()) return association_options.status();
  if (absl::Status s = association_options->Validate(); !s.ok()) {
    return absl::InvalidArgumentError(absl::StrCat("sensor '", sensor.name, "': ", s.message()));
  }
  RadarCalibrationRun run;
  run.expected = *std::move(expected);
  const std::vector<RadarCycle> used = CalibrationCycles(cycles, sensor);
  run.association = AssociateReflectors(used, run.expected, *association_options);
  run.result = CalibrateRadarYaw(sensor, run.expected, run.association, options);
  return run;
}

}  // namespace linecal
