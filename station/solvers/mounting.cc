#include "station/solvers/mounting.h"

#include <Eigen/Geometry>
#include <cmath>
#include <numbers>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"

namespace linecal {
namespace {

constexpr double kDegPerRad = 180.0 / std::numbers::pi;

double WrapAngle(double a) { return std::remainder(a, 2 * std::numbers::pi); }

Eigen::Vector3d AnglesVector(const YawPitchRoll& a) { return {a.yaw, a.pitch, a.roll}; }

}  // namespace

MountingEstimate MountingFromCarPose(const Rigid3d& T_car_sensor,
                                     const Eigen::Matrix<double, 6, 6>& covariance,
                                     const SensorModel& sensor) {
  const Eigen::Matrix3d r_base = SensorBaseRotation(sensor.kind);
  MountingEstimate m;
  m.T_car_sensor = T_car_sensor;
  const Eigen::Matrix3d R = T_car_sensor.RotationMatrix();
  m.angles = MountingAngles(R, r_base);
  m.position_m = T_car_sensor.translation();
  const YawPitchRoll nominal = MountingAngles(sensor.T_car_sensor_nominal.RotationMatrix(), r_base);
  m.angles_deviation = {WrapAngle(m.angles.yaw - nominal.yaw),
                        WrapAngle(m.angles.pitch - nominal.pitch),
                        WrapAngle(m.angles.roll - nominal.roll)};
  m.position_deviation_m = m.position_m - sensor.T_car_sensor_nominal.translation();
  // Yaw/pitch/roll as functions of the car-frame rotation vector, by central differences:
  // the angles are smooth away from pitch = ±90°, and 1e-6 rad keeps the truncation error
  // (~1e-12) and the rounding error (~1e-10 relative) far below any reported sigma.
  constexpr double kStep = 1e-6;
  Eigen::Matrix3d d_angles;
  for (int k = 0; k < 3; ++k) {
    const Eigen::Matrix3d plus =
        Eigen::AngleAxisd(kStep, Eigen::Vector3d::Unit(k)).toRotationMatrix() * R;
    const Eigen::Matrix3d minus =
        Eigen::AngleAxisd(-kStep, Eigen::Vector3d::Unit(k)).toRotationMatrix() * R;
    const Eigen::Vector3d a = AnglesVector(MountingAngles(plus, r_base));
    const Eigen::Vector3d b = AnglesVector(MountingAngles(minus, r_base));
    for (int i = 0; i < 3; ++i) d_angles(i, k) = WrapAngle(a[i] - b[i]) / (2 * kStep);
  }
  Eigen::Matrix<double, 6, 6> A = Eigen::Matrix<double, 6, 6>::Identity();
  A.topLeftCorner<3, 3>() = d_angles;
  m.sigma = (A * covariance * A.transpose()).diagonal().cwiseMax(0.0).cwiseSqrt();
  return m;
}

MountingEstimate MountingFromSensorPose(const Rigid3d& T_sensor_car,
                                        const Eigen::Matrix<double, 6, 6>& covariance,
                                        const SensorModel& sensor) {
  // Covariance of T_car_sensor = T_sensor_car^-1 with R_sc = exp(δθ) R̂_sc, t_sc = t̂ + δt:
  //   R_cs = R̂_scᵀ exp(-δθ) = exp(-R̂_cs δθ) R̂_cs             =>  δθ_car = -R̂_cs δθ
  //   t_cs = -R_cs t_sc ≈ t̂_cs - R̂_cs δt - R̂_cs [t̂_sc]x δθ
  const Rigid3d T_car_sensor = T_sensor_car.Inverse();
  const Eigen::Matrix3d R_cs = T_car_sensor.RotationMatrix();
  Eigen::Matrix<double, 6, 6> J = Eigen::Matrix<double, 6, 6>::Zero();
  J.topLeftCorner<3, 3>() = -R_cs;
  J.bottomLeftCorner<3, 3>() = -R_cs * Skew(T_sensor_car.translation());
  J.bottomRightCorner<3, 3>() = -R_cs;
  return MountingFromCarPose(T_car_sensor, J * covariance * J.transpose(), sensor);
}

ToleranceDecision DecideTolerance(double deviation, double sigma, double tolerance,
                                  double guard_sigmas) {
  const double u = guard_sigmas * sigma;
  if (std::abs(deviation) + u <= tolerance) return ToleranceDecision::kInside;
  if (std::abs(deviation) - u > tolerance) return ToleranceDecision::kOutside;
  return ToleranceDecision::kUndecided;
}

MountingJudgement JudgeMounting(const SensorModel& sensor, const MountingEstimate& m,
                                double max_sigma_fraction_of_tolerance) {
  const MountingTolerance& tol = sensor.tolerance;
  const double tolerances[6] = {tol.yaw_rad,   tol.pitch_rad, tol.roll_rad,
                                tol.xyz_m.x(), tol.xyz_m.y(), tol.xyz_m.z()};
  const Eigen::Matrix<double, 6, 1> deviations = m.Deviation();
  const char* names[6] = {"yaw", "pitch", "roll", "x", "y", "z"};
  // Angles are shown in degrees, positions in millimetres.
  auto shown = [](int i, double v) { return i < 3 ? v * kDegPerRad : v * 1e3; };
  const char* units[6] = {"deg", "deg", "deg", "mm", "mm", "mm"};
  MountingJudgement j;
  for (int i = 0; i < 6; ++i) {
    // A zero tolerance means "not checked" (e.g. a position the station cannot observe).
    if (!m.observed[i] || !(tolerances[i] > 0)) continue;
    if (m.sigma[i] > max_sigma_fraction_of_tolerance * tolerances[i]) {
      j.reason = "uncertainty_too_high";
      j.message =
          absl::StrFormat("%s: %s 1-sigma %.4f %s is above %.2f of its tolerance %.4f %s",
                          sensor.name, names[i], shown(i, m.sigma[i]), units[i],
                          max_sigma_fraction_of_tolerance, shown(i, tolerances[i]), units[i]);
      return j;
    }
  }
  std::string out_of_tolerance, undecided;
  for (int i = 0; i < 6; ++i) {
    if (!m.observed[i] || !(tolerances[i] > 0)) continue;
    const ToleranceDecision d = DecideTolerance(deviations[i], m.sigma[i], tolerances[i]);
    if (d == ToleranceDecision::kInside) continue;
    std::string& list = d == ToleranceDecision::kOutside ? out_of_tolerance : undecided;
    if (d == ToleranceDecision::kOutside && out_of_tolerance.empty())
      j.reason = absl::StrCat(names[i], "_out_of_tolerance");
    absl::StrAppendFormat(&list, "%s%s %+.3f %s (2 sigma %.3f, tolerance %.3f)",
                          list.empty() ? "" : ", ", names[i], shown(i, deviations[i]), units[i],
                          shown(i, kVerdictGuardSigmas * m.sigma[i]), shown(i, tolerances[i]));
  }
  if (!out_of_tolerance.empty()) {
    j.verdict = Verdict::kFail;
    j.message = absl::StrCat(sensor.name, ": out of tolerance: ", out_of_tolerance);
  } else if (!undecided.empty()) {
    j.reason = "near_tolerance_edge";
    j.message = absl::StrCat(sensor.name,
                             ": too close to a tolerance edge to tell pass from fail: ", undecided,
                             "; measure again or check the mounting by hand");
  } else {
    j.verdict = Verdict::kPass;
  }
  return j;
}

}  // namespace linecal
