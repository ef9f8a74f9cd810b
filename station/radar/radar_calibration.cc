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

  YawPitchRoll angles = nominal;
  double information = 0;
  for (int it = 0; it < kMaxIterations; ++it) {
    double jtj = 0, jtr = 0;
    for (const Used& u : used) {
      const double w = 1 / (u.observed->azimuth_se_rad * u.observed->azimuth_se_rad);
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
  out.yaw_sigma_measurement_rad = 1 / std::sqrt(information);
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
        const double w = 1 / (u.observed->azimuth_se_rad * u.observed->azimuth_se_rad);
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
  out.yaw_sigma_rad = std::hypot(out.yaw_sigma_measurement_rad, out.yaw_sigma_pitch_roll_rad);
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
