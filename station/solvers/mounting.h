#pragma once
// A sensor's mounting on the car as the solvers estimate it, and the verdict against the car
// model's tolerances: one implementation for cameras and LiDARs (and the vocabulary radars
// report in).
//
// Angles per docs/conventions.md: R_car_sensor = Rz(yaw) Ry(pitch) Rx(roll) R_base, R_base by the
// sensor kind (SensorBaseRotation).

#include <Eigen/Core>
#include <array>
#include <string>

#include "detectors/core/pose.h"
#include "station/model/car_model.h"
#include "station/model/verdict.h"

namespace linecal {

// A sensor's mounting in the car: angles (radians) and position (metres) with their 1-sigma,
// and the deviation from the nominal mounting.
struct MountingEstimate {
  Rigid3d T_car_sensor;
  YawPitchRoll angles;
  Eigen::Vector3d position_m = Eigen::Vector3d::Zero();
  YawPitchRoll angles_deviation;  // measured - nominal, wrapped to (-pi, pi]
  Eigen::Vector3d position_deviation_m = Eigen::Vector3d::Zero();
  // 1-sigma of yaw, pitch, roll (radians), x, y, z (metres).
  Eigen::Matrix<double, 6, 1> sigma = Eigen::Matrix<double, 6, 1>::Zero();
  // Which of yaw, pitch, roll, x, y, z were measured; the others are the nominal values,
  // with no deviation and no sigma to report (e.g. a radar without elevation: yaw only).
  std::array<bool, 6> observed = {true, true, true, true, true, true};

  // yaw, pitch, roll (radians), x, y, z (metres) of the deviation, in the order of `sigma`.
  Eigen::Matrix<double, 6, 1> Deviation() const {
    Eigen::Matrix<double, 6, 1> d;
    d << angles_deviation.yaw, angles_deviation.pitch, angles_deviation.roll, position_deviation_m;
    return d;
  }
};

// One board's share of a solved fit: the RMS of its own features' residuals at the solved
// mounting (a camera's reprojection errors in pixels over all frames, a LiDAR's hole-centre
// distances in metres). The sensor's residual RMS pools every board, so a board moved from
// its surveyed place is diluted there; here it stands alone (docs/console.md, "Moved-target
// alarm").
struct BoardResidual {
  std::string board_id;
  double rms = 0;
  int features = 0;  // residuals pooled (detections, hole centres)
};

// The mounting of a sensor whose pose is T_sensor_car, with the covariance of that pose as
// PnpResult gives it: (δθ, δt), the left rotation vector and the translation, both in the
// sensor frame. Propagates the covariance to yaw/pitch/roll and the position in the car
// frame. O(1).
MountingEstimate MountingFromSensorPose(const Rigid3d& T_sensor_car,
                                        const Eigen::Matrix<double, 6, 6>& covariance,
                                        const SensorModel& sensor);

// The same from T_car_sensor and the covariance of (δθ, δt) in the car frame (R_car_sensor =
// exp(δθ) R̂, t = t̂ + δt), as a solver in the car frame gives it. O(1).
MountingEstimate MountingFromCarPose(const Rigid3d& T_car_sensor,
                                     const Eigen::Matrix<double, 6, 6>& covariance,
                                     const SensorModel& sensor);

struct MountingJudgement {
  Verdict verdict = Verdict::kError;
  // "", "uncertainty_too_high", "<yaw|pitch|roll|x|y|z>_out_of_tolerance",
  // "near_tolerance_edge"
  std::string reason;
  std::string message;  // for a person; empty on pass
};

// The guard band of every verdict, in multiples of the component's 1-sigma: the decision rule
// of ISO 14253-1 with the expanded uncertainty U = 2 sigma (coverage factor 2, as the GUM).
// Conformity is shown when |deviation| + U <= tolerance, non-conformity when
// |deviation| - U > tolerance; between the two the measurement cannot tell, and a verdict
// from the estimate alone would be wrong for about one car in six of those whose truth lies
// 1 sigma inside or outside the edge (issue 20's bar: no verdict wrong with the truth more
// than 1 sigma from an edge; docs/solvers.md, "Verdicts near a tolerance edge").
inline constexpr double kVerdictGuardSigmas = 2.0;

// What one component's estimate shows against its tolerance (all > 0 but the deviation).
enum class ToleranceDecision { kInside, kOutside, kUndecided };

// The decision above for one component: kInside when |deviation| + guard·sigma <= tolerance,
// kOutside when |deviation| - guard·sigma > tolerance, else kUndecided. Pure, O(1).
ToleranceDecision DecideTolerance(double deviation, double sigma, double tolerance,
                                  double guard_sigmas = kVerdictGuardSigmas);

// The verdict of a trustworthy estimate against sensor.tolerance: error
// "uncertainty_too_high" when an observed component's 1-sigma exceeds
// max_sigma_fraction_of_tolerance of its tolerance (the verdict could not be trusted); else
// fail with the first component shown out of tolerance (DecideTolerance) in the order yaw,
// pitch, roll, x, y, z (the message lists all, in degrees and millimetres); else error
// "near_tolerance_edge" when a component is undecided (the message names it: measure again or
// check the mounting by hand); else pass. A zero tolerance and an unobserved component are not
// judged. O(1).
MountingJudgement JudgeMounting(const SensorModel& sensor, const MountingEstimate& mounting,
                                double max_sigma_fraction_of_tolerance);

}  // namespace linecal
