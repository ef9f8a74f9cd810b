#pragma once
// Radar-to-car calibration from corner reflectors: the mounting yaw, its uncertainty and a
// verdict (docs/lidar-radar.md, "Radar calibration").
//
// The ARS408 and the ESR report range and azimuth but no elevation, so only the rotation
// about the radar's vertical is observable from reflector azimuths: pitch and roll are taken
// as nominal (they move a reflector's azimuth only to second order, or through its height
// difference, which the station keeps small), and so is the height. The horizontal position
// is estimated with the yaw, as far as the reflectors tell it: an offset δ across a
// reflector's line of sight moves its azimuth by δ / range, which differs from the yaw's
// effect only between reflectors at different ranges or bearings; the rest of the position
// tolerance stays in the σ.
//
// Model: R_car_radar(yaw) = Rz(yaw) · Ry(pitch_nominal) · Rx(roll_nominal) · R_base (R_base =
// identity for radars), t_car_radar = t_nominal + (dx, dy, 0); a reflector at p_car is
// expected at azimuth atan2(y, x) of p_radar = R_car_radarᵀ · (p_car − t_car_radar). (yaw, dx,
// dy) minimise Σ ((azimuth_measured − azimuth_expected) / se)² + dx² / v_x + dy² / v_y over
// the found reflectors, v the variance of an offset uniform within ±the position tolerance
// (Gauss-Newton in three unknowns; with reflectors at one range the prior decides the offset
// and the yaw is the yaw-only fit). The yaw's 1-σ combines, in quadrature, the
// measurement part (each reflector's standard error through the fit's yaw gain), the part of
// the true offset that the prior's pull towards nominal leaves in the yaw (offset uniform within
// ±tolerance), the part that pitch and roll errors within their tolerance alias into yaw
// (Ry(pitch)·Rx(roll) turns the boresight about the vertical by about pitch·roll/2, and pitch moves
// off-axis azimuths to second order: the RMS over pitch and roll uniform in ±tolerance of the yaw
// shift they cause, 3x3-point Gauss-Legendre quadrature), and, for radars that report Cartesian
// positions in a grid (ARS408), the part the grid's rounding leaves: the reflectors' rounding
// errors are modelled jointly, as the RMS over every lateral place of the reflector set in the
// grid of the yaw error they cause together.

#include <span>
#include <string>
#include <vector>

#include "detectors/core/pose.h"
#include "station/model/car_model.h"
#include "station/model/verdict.h"
#include "station/solvers/mounting.h"
#include "station/solvers/reflector_association.h"

namespace linecal {

struct RadarCalibrationOptions {
  // Fewer found reflectors give error too_few_reflectors. Two are the least that let a bad
  // association show as a residual; one would give a yaw nobody could check.
  int min_reflectors = 2;
  // A yaw 1-σ above this fraction of the yaw tolerance gives error uncertainty_too_high: a
  // verdict needs the estimate to be clearly inside or outside ±tolerance (at 1/3, a 3σ band
  // spans the tolerance).
  double max_sigma_fraction_of_tolerance = 1.0 / 3.0;
  // OK or InvalidArgument naming the first bad field. O(1).
  absl::Status Validate() const;
};

// One reflector's part in the fit.
struct RadarReflectorResidual {
  std::string reflector_id;
  double azimuth_measured_rad = 0;
  double azimuth_predicted_rad = 0;  // at the estimated yaw
  double azimuth_se_rad = 0;
  double residual_rad = 0;  // measured − predicted
};

struct RadarCalibrationResult {
  Verdict verdict = Verdict::kError;
  // "" for pass; "yaw_out_of_tolerance" for fail; "too_few_reflectors" or
  // "uncertainty_too_high" or "near_tolerance_edge" (mounting.h, DecideTolerance) for error.
  std::string reason;
  int reflectors_used = 0;
  // Mounting angles (docs/conventions.md), radians. Pitch and roll are the nominal ones: not
  // observable without elevation.
  double yaw_rad = 0;
  double yaw_sigma_rad = 0;              // total 1-σ: the four parts below in quadrature
  double yaw_sigma_measurement_rad = 0;  // from the reflectors' standard errors
  double yaw_sigma_pitch_roll_rad = 0;   // pitch and roll unknown within their tolerance
  // The radar's position grid (ARS408), whose rounding errors all reflectors share; 0 for
  // radars that report polar values (ESR), whose steps are in the standard errors.
  double yaw_sigma_position_steps_rad = 0;
  // The radar's horizontal offset from nominal, uniform within ±tolerance, as far as the fit
  // leaves it in the yaw (all of it with reflectors at one range).
  double yaw_sigma_position_rad = 0;
  // Half-width of the 95% interval around yaw_rad. 1.96 yaw_sigma_rad when the error is
  // Gaussian; a position grid's error is not (a sum of a few sawtooths is closer to uniform),
  // nor is a uniform position offset's, so it is the mixture over the grid's lateral shifts
  // and the offsets of the Gaussian parts around the error they leave.
  double yaw_ci95_rad = 0;
  double nominal_yaw_rad = 0;
  double yaw_deviation_rad = 0;  // yaw − nominal yaw
  double yaw_tolerance_rad = 0;
  double pitch_rad = 0;
  double roll_rad = 0;
  bool pitch_observable = false;  // always false for these radars; reported so nobody assumes
  // Estimated (x, y) offset from the nominal position, car frame, metres, and its 1-σ (prior
  // included: about tolerance / √3 where the reflectors do not tell it).
  Eigen::Vector2d position_offset_m = Eigen::Vector2d::Zero();
  Eigen::Vector2d position_offset_sigma_m = Eigen::Vector2d::Zero();
  // Estimated yaw and horizontal position, nominal pitch, roll and height.
  Rigid3d T_car_radar;
  // Normalised residuals: Σ (residual / se)² and its degrees of freedom (reflectors − 1).
  double chi2 = 0;
  int dof = 0;
  std::vector<RadarReflectorResidual> residuals;
};

// Solves the radar's yaw from the found reflectors of `association` (other statuses are
// skipped), whose `expected` (same order, from ExpectedReflectors) gives each reflector's
// car-frame position, and judges it against sensor.tolerance.yaw_rad. Needs a radar sensor
// (the caller has checked it: ExpectedReflectors fails otherwise). Outcomes, not failures,
// are in the verdict. Cost: O(reflectors) per iteration, ≤ 20 iterations.
RadarCalibrationResult CalibrateRadarYaw(const SensorModel& sensor,
                                         std::span<const ExpectedReflector> expected,
                                         const ReflectorAssociation& association,
                                         const RadarCalibrationOptions& options);

// The cycles of `all` that calibration uses for `sensor`: ARS408 cluster lists of its
// radar_sensor_id (clusters are single reflections; the object list is the sensor's tracking
// of them and would count each reflector twice), ESR track scans. Copies. O(cycles).
std::vector<RadarCycle> CalibrationCycles(std::span<const RadarCycle> all,
                                          const SensorModel& sensor);

// The whole chain for one radar: expected reflectors from the nominal mounting and
// T_station_car, association (ReflectorAssociationOptions::ForSensor), yaw and verdict.
struct RadarCalibrationRun {
  std::vector<ExpectedReflector> expected;
  ReflectorAssociation association;
  RadarCalibrationResult result;
};
// Errors (InvalidArgument / NotFound) as ExpectedReflectors and the options' Validate;
// everything else is an outcome in the result. Cost: O(cycles · detections · targets).
absl::StatusOr<RadarCalibrationRun> CalibrateRadar(const SensorModel& sensor,
                                                   const StationLayout& layout,
                                                   const Rigid3d& T_station_car,
                                                   std::span<const RadarCycle> cycles,
                                                   const RadarCalibrationOptions& options);

// The azimuth (radians) at which a radar at t_car_radar with mounting angles `angles`
// (R_base = identity) sees the point p_car. Exposed for the derivative test. O(1).
double PredictedAzimuth(const YawPitchRoll& angles, const Eigen::Vector3d& t_car_radar,
                        const Eigen::Vector3d& p_car);

// ∂PredictedAzimuth/∂t_car_radar (per metre along x, y, z of the car frame), analytic. O(1).
Eigen::Vector3d PredictedAzimuthPositionDerivative(const YawPitchRoll& angles,
                                                   const Eigen::Vector3d& t_car_radar,
                                                   const Eigen::Vector3d& p_car);

// ∂PredictedAzimuth/∂yaw, analytic. O(1).
double PredictedAzimuthYawDerivative(const YawPitchRoll& angles, const Eigen::Vector3d& t_car_radar,
                                     const Eigen::Vector3d& p_car);

}  // namespace linecal
