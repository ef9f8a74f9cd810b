#pragma once
// Which radar detections are the station's corner reflectors, and where each reflector is on
// average: the first half of radar calibration (docs/lidar-radar.md, "Radar calibration").
//
// Input: decoded measurement cycles of ONE radar (station/sensors/radar/radar_format.h) and each
// target reflector's expected range and azimuth in the radar frame, computed from the NOMINAL
// mounting, the aligner's T_station_car and the station layout (ExpectedReflectors). Per cycle
// and reflector, a detection is a candidate when it lies in a gate around the expected range
// and azimuth, is static (|range rate| small) and, where the model reports RCS (ARS408, not
// the ESR), is strong. Of the candidates the nearest in range wins: multipath ghosts come back
// farther and weaker, clutter that passes the gates is rare and is removed by the robust
// averaging (median / MAD rejection, then the mean of the rest).

#include <numbers>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "detectors/core/pose.h"
#include "station/model/car_model.h"
#include "station/model/station_layout.h"
#include "station/sensors/radar/field_of_view.h"
#include "station/sensors/radar/radar_format.h"

namespace linecal {

// The resolution of what a radar model reports, as its CAN messages quantise it. A step that
// the detection noise does not dither leaves a bias that averaging over cycles cannot remove.
struct RadarResolution {
  double position_step_m = 0;      // Cartesian x and y steps (ARS408 clusters: DistLong/DistLat)
  double position_x_origin_m = 0;  // an x value the grid holds (ARS408: DistLong's offset)
  double range_step_m = 0;         // polar range step (ESR)
  double azimuth_step_rad = 0;     // polar azimuth step (ESR)
};

// "ars408": 0.2 m per axis (cluster DistLong/DistLat), x grid through −500 m; "esr": 0.1 m and
// 0.1° (track range and angle), as radar_format.h's signals. nullopt for other names. O(1).
std::optional<RadarResolution> RadarResolutionOf(const std::string& model);

// A target reflector as the radar should see it if mounted exactly as nominal.
struct ExpectedReflector {
  std::string reflector_id;
  Eigen::Vector3d p_car = Eigen::Vector3d::Zero();  // metres, car frame
  double range_m = 0;                               // in the nominal radar frame
  double azimuth_rad = 0;                           // counter-clockwise from the boresight
  bool in_view = false;  // inside the model's field of view and range (RadarFieldOfViewOf)
};

// The sensor's targets (SensorModel::targets, in that order) as seen from its nominal mounting
// for a car at T_station_car. Errors: InvalidArgument when the sensor is not a radar or its
// model is unknown, NotFound naming a target that the layout lacks. O(targets · reflectors).
absl::StatusOr<std::vector<ExpectedReflector>> ExpectedReflectors(const SensorModel& sensor,
                                                                  const StationLayout& layout,
                                                                  const Rigid3d& T_station_car);

struct ReflectorAssociationOptions {
  // Half-widths of the gate around the expected azimuth and range. The azimuth gate must
  // cover the mounting yaw error to be measured (tolerance and beyond) plus 3σ of the noise.
  double azimuth_gate_rad = 0.05;  // ~2.9°: 2 x a 1° tolerance + 3σ + margins (see ForSensor)
  double range_gate_m = 0.6;       // ForSensor: position tolerance + noise + resolution
  // The lateral margin of the azimuth gate (ForSensor: the position tolerance and half a
  // position step), metres across the line of sight. azimuth_gate_rad holds it as the angle it
  // spans at 4 m; a reflector nearer than that gets the rest of its angle on top (at 2 m a 7 cm
  // margin spans 2°, not 1°), so that a radar off its place still finds its near reflectors.
  double azimuth_gate_lateral_m = 0;
  // Station clutter (floor, stands, people) stays below ~5 dBm² while corner reflectors are
  // ≥ 10 dBm²; applied only to detections that carry RCS.
  double min_rcs_dbsm = 8.0;
  // The car stands still: a reflector's range rate is noise (~0.03 m/s) plus one ARS408
  // quantisation step (0.25 m/s / 2); people and cars passing by move faster.
  double max_abs_range_rate_mps = 0.3;
  // Fewer accepted detections than this (after outlier rejection) give too_few_detections:
  // a 20% detection rate over 50 cycles still averages the azimuth noise down by 3x.
  int min_detections = 10;
  // Two candidates of one cycle closer in range than this cannot be told apart by "nearest
  // wins"; the cycle is skipped for that reflector. Half of the cycles so skipped make the
  // reflector ambiguous.
  double ambiguity_range_m = 0.3;
  // Robust rejection: a detection farther than this many robust σ (1.4826 x MAD, floored by
  // the noise and the resolution) from the median azimuth or range is an outlier. 3.5 is the
  // usual modified-z-score cut (Iglewicz and Hoaglin); Gaussian noise loses < 0.1%.
  double outlier_z = 3.5;
  // Nominal per-detection noise of the sensor (docs/acceptance.md: 0.1° azimuth): sizes the
  // gates and floors the robust scale of the outlier test. The standard errors use the noise
  // estimated from the capture itself (EstimateDetectionNoise), not these.
  double detection_azimuth_sigma_rad = 0.1 * std::numbers::pi / 180;
  double detection_range_sigma_m = 0.05;
  RadarResolution resolution;

  // OK or InvalidArgument naming the first bad field. O(1).
  absl::Status Validate() const;

  // Options for a radar of the car model: gates from its yaw and position tolerance
  // (azimuth gate = 2 x yaw tolerance + 3σ + a margin for position tolerance and resolution,
  // so that mountings up to twice out of tolerance are still measured and judged), the model's
  // resolution. InvalidArgument for a non-radar sensor or an unknown model. O(1).
  static absl::StatusOr<ReflectorAssociationOptions> ForSensor(const SensorModel& sensor);
};

enum class ReflectorStatus {
  kFound,
  kNotInView,         // outside the field of view or range seen from the nominal mounting
  kNoDetections,      // no candidate in its gate in any cycle
  kTooFewDetections,  // fewer than min_detections after outlier rejection
  kAmbiguous,         // its gate overlaps another reflector's, or most cycles were ambiguous
};

// "found", "not_in_view", "no_detections", "too_few_detections", "ambiguous".
const char* ReflectorStatusName(ReflectorStatus status);

// One reflector's averaged measurement in the radar frame.
struct ReflectorObservation {
  std::string reflector_id;
  ReflectorStatus status = ReflectorStatus::kNoDetections;
  double expected_range_m = 0;
  double expected_azimuth_rad = 0;
  int cycles_with_candidates = 0;
  int ambiguous_cycles = 0;
  int outliers = 0;  // rejected by the median/MAD test
  int n_used = 0;    // detections averaged
  // Means of the used detections and their standard errors: the scatter (not below the
  // capture's estimated noise, itself not below a polar step / √12: quantised values may not
  // vary at all) over √n, plus (in quadrature) the bias of resolution steps that the estimated
  // noise does not dither. Valid when found.
  double range_m = 0;
  double range_se_m = 0;
  double azimuth_rad = 0;
  double azimuth_se_rad = 0;
  // azimuth_se_rad without the bias of Cartesian position steps (RadarResolution::
  // position_step_m). That bias depends on where the reflector sits in the position grid, which
  // is shared by every reflector of a radar; radar_calibration.h models it jointly over the
  // reflectors instead of as an independent error of each.
  double azimuth_se_without_position_steps_rad = 0;
};

// The per-detection noise of one radar in one capture, estimated from the data.
struct DetectionNoise {
  // Range and azimuth noise 1-σ before the radar's rounding to its resolution steps. 0 (1 mm
  // of range on the ARS408's grid) when nothing varied, 0 when no reflector was found: then
  // every resolution step is taken as undithered, the largest bias it can leave.
  double range_sigma_m = 0;
  double azimuth_sigma_rad = 0;
  int dof = 0;  // Σ (detections − 1) over the reflectors pooled
};

// One reflector's detections of a capture, after outlier rejection.
struct ReflectorDetections {
  std::vector<double> range_m;
  std::vector<double> azimuth_rad;  // same length
};

// The noise of a capture from the scatter of each reflector's repeated detections about its own
// mean (the reflectors stand still, so that scatter is the noise), undoing the rounding to the
// resolution steps.
// - Polar steps (ESR), per quantity, by the method of moments: for noise r (in steps) and a true
//   value anywhere in its cell, the expected within-reflector variance of the rounded readings
//   is W(r) = r² + 1/12 − Σₖ exp(−4π²k²r²) / (2π²k²) steps² (the rounding's variance less that
//   of its mean, which stays fixed within a reflector); the pooled variance is solved for r.
// - The ARS408's Cartesian grid: the range noise that maximises the likelihood of every
//   reflector's cell counts in x and y (noise hypot(σr·cos, σa·R·sin) in x, the converse in y),
//   each reflector's place in its cells integrated out. Moments fail there: with noise below the
//   step the within-reflector variance is decided by where a reflector sits in its cell. The
//   azimuth noise is `grid_azimuth_sigma_rad` (reported as such): 0.1° is 0.05–0.12 of a 0.2 m
//   cell across the line of sight at 6–14 m, which no capture separates from the range noise.
// Reflectors with fewer than two detections are skipped. Cost: O(detections + reflectors · 10³)
// polar; O(reflectors · 10⁵) on the grid (≈ 10 ms for 6 reflectors).
DetectionNoise EstimateDetectionNoise(std::span<const ReflectorDetections> reflectors,
                                      const RadarResolution& resolution,
                                      double grid_azimuth_sigma_rad = 0.1 * std::numbers::pi / 180);

struct ReflectorAssociation {
  int cycles = 0;                                // cycles examined
  std::vector<ReflectorObservation> reflectors;  // in the order of `expected`
  // The measurement model the standard errors assume: how the radar quantises positions and
  // how much the per-detection noise of this capture (estimated from it) dithers that.
  RadarResolution resolution;
  DetectionNoise noise;
};

// Associates detections with reflectors over `cycles` (one radar; cycles of one list kind,
// e.g. ARS408 clusters, should be passed: mixing lists counts a reflector twice per cycle).
// Pure function; failures are per-reflector statuses. Requires options.Validate() to be OK.
// Cost: O(cycles · detections · reflectors + n log n per reflector).
ReflectorAssociation AssociateReflectors(std::span<const RadarCycle> cycles,
                                         std::span<const ExpectedReflector> expected,
                                         const ReflectorAssociationOptions& options);

}  // namespace linecal
