#pragma once
// The board placement planner (docs/planner.md): for a car model and a station's floor
// limits, where to put the calibration boards and radar reflectors so that every sensor can
// be calibrated (PlanLayout); for an existing layout, which sensors can be calibrated and
// why not (AssessLayout); and for every planned sensor-target pair the region in which the
// target may be moved and still work (ValidRegionOf).
//
// The car stands at the station origin (T_station_car = identity, the aligner's nominal) and
// every sensor at its nominal mounting. A sensor is calibratable when every one of its
// targets passes the geometric checks below and the uncertainty the solvers predict for the
// layout is within max_sigma_fraction_of_tolerance of every tolerance (the solvers' own
// uncertainty_too_high bar). The predicted uncertainty comes from the solvers themselves:
//   camera  the targets' features projected exactly through the nominal camera, fed to
//           CalibrateCamera with the configured corner noise (its PnP covariance moved to
//           yaw/pitch/roll and position);
//   LiDAR   one rotation of the LiDAR simulator over the layout, the real round-hole
//           detector on it (its fit's hole-centre sigma), CalibrateLidar on the exact hole
//           centres with that sigma;
//   radar   detections of the reflectors over radar_cycles cycles with the sensor's noise
//           and resolution (fixed seed) through the real association and CalibrateRadarYaw;
//           for a position grid (ARS408) the RMS over eight lateral shifts of the grid.
//
// Reason codes (a sensor lists each code once, in this order of checks):
//   unknown_target         a target id the layout does not have
//   wrong_target_type      a LiDAR target that is not a round-hole board, a radar target
//                          that is not a reflector
//   board_outside_fov      a board (or part of it) outside the camera image, behind the
//                          sensor, turned away from it, or out of the LiDAR's range
//   reflector_outside_fov  a reflector outside the radar's azimuth field of view or range
//   features_too_small     a camera board's smallest square or marker cell images smaller
//                          than min_feature_px
//   too_few_rings          fewer than min_rings_per_hole LiDAR rings through some hole
//   occluded_by_board      another board blocks the line of sight to a target feature
//   occluded_by_surface    a surface of the layout (a wall, a screen) blocks it
//   in_keep_out            the target's footprint overlaps a keep-out zone
//   outside_usable_area    the footprint leaves the usable area or crosses a wall
//   outside_height_limits  the target reaches below or above the height limits
//   board_not_detected     the simulated LiDAR scan does not let the detector find it
//   too_few_features       the targets pass but are not enough for a solve (not reported
//                          when a target failed one of the checks above: that is the reason)
//   uncertainty_above_tolerance  predicted 1-sigma above the fraction of a tolerance

#include <Eigen/Core>
#include <array>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "station/model/car_model.h"
#include "station/model/station_layout.h"
#include "station/planner/floor_limits.h"

namespace linecal {

struct PlannerOptions {
  double min_feature_px = 15;    // smallest imaged square / marker cell, (0, 1000]
  double corner_noise_px = 0.1;  // camera feature noise of the prediction, (0, 10]
  // The same for fisheye cameras, whose boards are found in resampled perspective views
  // (station/camera/board_view.h) and so have their own noise; 0: corner_noise_px. [0, 10]
  double fisheye_corner_noise_px = 0;
  int camera_frames = 1;       // frames per camera the calibration will use, 1..100
  double image_margin_px = 8;  // features this far inside the image, [0, 500]
  // Plan only: a new camera board's image bounding box covers at least / at most this
  // share of the image. (0, 1].
  // The default keeps a camera's board to a tenth of its view, leaving the rest for the
  // other sensors' targets.
  double min_fill_share = 0.005;
  double max_fill_share = 0.1;
  int min_rings_per_hole = 2;  // [1, 64]
  int radar_cycles = 20;       // [10, 10000]: what the simulator and a cycle record
  double max_sigma_fraction_of_tolerance = 1.0 / 3.0;  // (0, 10]
  // Plan only: compute the valid regions (the slow part).
  bool regions = true;

  // OK or InvalidArgument naming the first bad field. O(1).
  absl::Status Validate() const;
};

struct TargetAssessment {
  std::string target;
  std::vector<std::string> reasons;  // empty: usable
  std::string detail;                // for a person: which board occludes, the numbers
  int features = 0;                  // features in view (cameras), holes (LiDARs)
  double smallest_feature_px = 0;    // cameras
  int fewest_rings = 0;              // LiDARs: rings through the worst hole
  // Boards: the share of the page (of what lies in the sensor's view) hidden behind other
  // boards and the layout's surfaces, and the board or surface hiding most of it ("" when
  // none). Without a hidden feature (occluded_by_board) the target stays usable: the
  // detectors find it from what shows.
  double hidden_share = 0;
  std::string hidden_by;
};

struct SensorAssessment {
  std::string sensor;
  SensorKind kind = SensorKind::kCamera;
  bool calibratable = false;
  std::vector<std::string> reasons;  // codes, each once; empty when calibratable
  std::vector<TargetAssessment> targets;
  bool sigma_valid = false;
  // Predicted 1-sigma of yaw, pitch, roll (rad) and x, y, z (m), with which are observed
  // (radars: yaw only).
  Eigen::Matrix<double, 6, 1> sigma = Eigen::Matrix<double, 6, 1>::Zero();
  std::array<bool, 6> observed = {true, true, true, true, true, true};
  // max over observed components of sigma / (fraction * tolerance): <= 1 is within.
  double uncertainty_ratio = 0;
};

// Assesses one sensor of the car against its targets in `layout`. `floor` may be null (no
// keep-out, area or height checks). predict_sigma = false skips the uncertainty (geometry
// only, fast). Errors (InvalidArgument): bad options, a camera without intrinsics, a LiDAR
// whose beam table cannot be read.
absl::StatusOr<SensorAssessment> AssessSensor(const SensorModel& sensor,
                                              const StationLayout& layout, const FloorLimits* floor,
                                              const PlannerOptions& options,
                                              bool predict_sigma = true);
// Every sensor of the car, in its order.
absl::StatusOr<std::vector<SensorAssessment>> AssessLayout(const CarModel& car,
                                                           const StationLayout& layout,
                                                           const FloorLimits* floor,
                                                           const PlannerOptions& options);

// Where a target of a sensor still works, the other targets fixed: the board (or
// reflector) moved along the sensor's horizontal line of sight (distance), across it
// (lateral), up and down (height) and turned about the vertical from facing the sensor
// (heading, boards only), each as the contiguous range around the planned pose; and the
// polygon (floor plane, station frame) of the centre positions, facing the sensor at the
// planned height, that work.
struct ValidRegion {
  std::string sensor;
  std::string target;
  double distance_min_m = 0, distance_max_m = 0;
  double lateral_min_m = 0, lateral_max_m = 0;  // + to the sensor's left
  double height_min_m = 0, height_max_m = 0;
  double heading_min_deg = 0, heading_max_deg = 0;  // 0 = facing the sensor
  FloorPolygon polygon;
};

// Errors as AssessSensor, and NotFound for a target not in the layout. Cost: about 10^3
// geometric assessments of the sensor, with the uncertainty where the geometry passes
// (LiDARs: CalibrateLidar at a fixed hole-centre sigma instead of the simulation).
absl::StatusOr<ValidRegion> ValidRegionOf(const SensorModel& sensor, const std::string& target,
                                          const StationLayout& layout, const FloorLimits* floor,
                                          const PlannerOptions& options);

struct StationPlan {
  StationLayout layout;  // boards, reflectors and the floor's walls as surfaces
  CarModel car;          // the input car with each sensor's targets set to its planned ones
  std::vector<SensorAssessment> sensors;
  std::vector<ValidRegion> regions;
};

// Plans a layout for `car` within `floor`: pinhole cameras first (one board from the
// catalogue each), then LiDARs (a pair of round-hole boards), fisheye cameras, radars
// (three reflectors across the field of view). A sensor first takes the boards already
// placed that it can use; when they do not suffice, the new target(s) are the candidate of
// lowest predicted uncertainty among those that pass every check and neither block nor are
// blocked by the targets already placed (when none does, the least bad one, and the
// sensor's assessment says why). Errors as AssessSensor.
absl::StatusOr<StationPlan> PlanLayout(const CarModel& car, const FloorLimits& floor,
                                       const PlannerOptions& options);

// Geometry helpers, exposed for the tests.

// The smallest imaged cell over the board's features, pixels: at each feature the image
// length of one cell along the board's x and y, over the features the lens can image
// (+infinity when none can). O(features).
double SmallestCellPx(const CameraModel& camera, const Rigid3d& T_camera_board, const Board& board);
// True when the segment a-b passes through the printed page of `board` (holes included:
// the planner does not count on seeing through them). Endpoints on the page do not count.
bool SegmentHitsBoard(const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                      const StationBoard& board);
// The board's footprint on the floor: its page corners projected to z = 0 (a segment for
// an upright board, which is where its stand goes). O(1).
FloorPolygon BoardFootprint(const StationBoard& board);
// Distinct rings (beams) of `beams` whose elevation crosses the hole of radius radius_m
// centred at p_lidar on a board with normal n_lidar (both LiDAR frame). O(beams).
int RingsThroughHole(const std::vector<double>& beam_elevations_rad,
                     const Eigen::Vector3d& centre_lidar, const Eigen::Vector3d& normal_lidar,
                     double radius_m);

}  // namespace linecal
