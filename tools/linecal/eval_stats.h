#pragma once
// The statistics the `linecal eval ...` programs share (eval_harness.h runs them): random cars,
// percentiles and the checks of a reported 1-sigma against the spread of the errors it
// describes (docs/acceptance.md).

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>
#include <random>
#include <span>
#include <vector>

#include "station/model/aligner.h"
#include "station/model/car_model.h"
#include "station/model/station_layout.h"
#include "station/solvers/mounting.h"

namespace linecal::tools {

// The two-sided 95% quantile of the standard normal distribution.
inline constexpr double kZ95 = 1.959964;

// The q-quantile (0..1) of v, linear between order statistics; 0 for an empty v. O(n log n).
inline double Percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  const double pos = q * static_cast<double>(v.size() - 1);
  const size_t lo = static_cast<size_t>(std::floor(pos));
  const size_t hi = std::min(lo + 1, v.size() - 1);
  return v[lo] + (pos - static_cast<double>(lo)) * (v[hi] - v[lo]);
}

struct ErrorSigmaStats {
  int n = 0;
  double p95_abs_error = 0;
  double rms_error = 0;
  double rms_sigma = 0;
  double error_over_sigma = 0;  // RMS error / RMS reported sigma: 1 when the sigma is right
  double coverage95 = 0;        // share of |error| <= 1.96 sigma: 0.95 when it is right
};

// errors[i] (estimate - truth) with their reported 1-sigma sigmas[i]; same length. O(n log n).
inline ErrorSigmaStats SummariseErrors(std::span<const double> errors,
                                       std::span<const double> sigmas) {
  ErrorSigmaStats s;
  s.n = static_cast<int>(errors.size());
  if (errors.empty()) return s;
  std::vector<double> abs_errors;
  double sum_e2 = 0, sum_s2 = 0;
  int covered = 0;
  for (size_t i = 0; i < errors.size(); ++i) {
    abs_errors.push_back(std::abs(errors[i]));
    sum_e2 += errors[i] * errors[i];
    sum_s2 += sigmas[i] * sigmas[i];
    covered += std::abs(errors[i]) <= kZ95 * sigmas[i];
  }
  const double n = static_cast<double>(errors.size());
  s.p95_abs_error = Percentile(std::move(abs_errors), 0.95);
  s.rms_error = std::sqrt(sum_e2 / n);
  s.rms_sigma = std::sqrt(sum_s2 / n);
  s.error_over_sigma = s.rms_sigma > 0 ? s.rms_error / s.rms_sigma : 0;
  s.coverage95 = covered / n;
  return s;
}

// A random car for the mounting evaluations: the aligner within the simulator's default
// bounds (simulator.h: ±2 cm, ±0.2°).
inline AlignerMeasurement RandomAligner(std::mt19937_64& rng) {
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  constexpr double kAlignerOffsetM = 0.02;
  constexpr double kAlignerThrustRad = 0.2 * std::numbers::pi / 180.0;
  AlignerMeasurement aligner;
  aligner.longitudinal_offset_m = kAlignerOffsetM * unit(rng);
  aligner.lateral_offset_m = kAlignerOffsetM * unit(rng);
  aligner.thrust_angle_rad = kAlignerThrustRad * unit(rng);
  return aligner;
}

// A sensor's true mounting: yaw, pitch, roll, x, y, z errors (in `truth`, radians and metres)
// applied to the nominal mounting, and the sensor's tolerances in the same order.
struct TrueMounting {
  std::array<double, 6> truth{};
  std::array<double, 6> tolerances{};
  Rigid3d T_car_sensor;
};
// The tolerances of yaw, pitch, roll (radians), x, y, z (metres) of `s`.
inline std::array<double, 6> MountingTolerances(const SensorModel& s) {
  const MountingTolerance& tol = s.tolerance;
  return {tol.yaw_rad, tol.pitch_rad, tol.roll_rad, tol.xyz_m.x(), tol.xyz_m.y(), tol.xyz_m.z()};
}
// The mounting of `s` whose yaw, pitch, roll, x, y, z errors are `truth` (radians, metres).
inline TrueMounting MountingWithErrors(const SensorModel& s, const std::array<double, 6>& truth) {
  TrueMounting m;
  m.tolerances = MountingTolerances(s);
  m.truth = truth;
  const Eigen::Matrix3d r_base = SensorBaseRotation(s.kind);
  const YawPitchRoll n = MountingAngles(s.T_car_sensor_nominal.RotationMatrix(), r_base);
  m.T_car_sensor = Rigid3d(
      MountingRotation({n.yaw + m.truth[0], n.pitch + m.truth[1], n.roll + m.truth[2]}, r_base),
      s.T_car_sensor_nominal.translation() + Eigen::Vector3d(m.truth[3], m.truth[4], m.truth[5]));
  return m;
}
inline TrueMounting RandomMounting(const SensorModel& s, double range_of_tolerance,
                                   std::mt19937_64& rng) {
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  const std::array<double, 6> tolerances = MountingTolerances(s);
  std::array<double, 6> truth{};
  for (int i = 0; i < 6; ++i) truth[i] = range_of_tolerance * tolerances[i] * unit(rng);
  return MountingWithErrors(s, truth);
}

// The estimates of one sensor over the cars: per component (yaw, pitch, roll, x, y, z) the
// errors and reported sigmas, and how often the verdict agreed with the truth where
// docs/acceptance.md judges it (every true error more than 2 sigma from the tolerance edge).
struct MountingSamples {
  std::vector<double> errors[6], sigmas[6];
  int verdicts_judged = 0, verdicts_agree = 0;

  void Add(const MountingEstimate& m, const TrueMounting& truth, Verdict verdict) {
    const Eigen::Matrix<double, 6, 1> estimate = m.Deviation();
    bool judgeable = true, truly_in = true;
    for (int i = 0; i < 6; ++i) {
      errors[i].push_back(estimate[i] - truth.truth[i]);
      sigmas[i].push_back(m.sigma[i]);
      judgeable &= std::abs(std::abs(truth.truth[i]) - truth.tolerances[i]) > 2 * m.sigma[i];
      truly_in &= std::abs(truth.truth[i]) <= truth.tolerances[i];
    }
    if (judgeable && verdict != Verdict::kError) {
      ++verdicts_judged;
      verdicts_agree += (verdict == Verdict::kPass) == truly_in;
    }
  }
};

struct MountingSummary {
  ErrorSigmaStats stats[6];
  double ratio_lo = 1e9, ratio_hi = 0, cover_lo = 1, cover_hi = 0;  // over the components
  double agreement = 1.0;  // share of judged verdicts that agree (1 when none was judged)
};
inline MountingSummary Summarise(const MountingSamples& c) {
  MountingSummary s;
  for (int i = 0; i < 6; ++i) {
    s.stats[i] = SummariseErrors(c.errors[i], c.sigmas[i]);
    s.ratio_lo = std::min(s.ratio_lo, s.stats[i].error_over_sigma);
    s.ratio_hi = std::max(s.ratio_hi, s.stats[i].error_over_sigma);
    s.cover_lo = std::min(s.cover_lo, s.stats[i].coverage95);
    s.cover_hi = std::max(s.cover_hi, s.stats[i].coverage95);
  }
  s.agreement = c.verdicts_judged ? static_cast<double>(c.verdicts_agree) / c.verdicts_judged : 1.0;
  return s;
}

}  // namespace linecal::tools
