#pragma once
// Camera-to-car calibration: every board feature a camera saw, in every frame, placed in the
// car frame through the station layout and the aligner (p_car = T_car_station *
// T_station_board * p_board) and solved jointly as one PnP problem (not per board and
// averaged; a feature seen in several frames of the still scene enters as its mean over them,
// so that the 1-sigma does not shrink with frames below what the data's scatter supports; each
// board type, i.e. detector, gets its own feature noise, pnp.h);
// then the mounting angles and position with their 1-sigma, the deviation from
// nominal, the verdict against the car model's tolerances, and what the car's own software
// derives from the extrinsic: the vanishing point of the car's forward direction, the
// camera-to-ground homography and a ranging check.
//
// Frames: T_car_camera maps camera coordinates to the car frame (ISO 8855, origin on the
// ground under the rear axle). Angles per docs/conventions.md: R_car_camera = Rz(yaw) Ry(pitch)
// Rx(roll) R_base.
//
// Verdicts: pass; fail with "<yaw|pitch|roll|x|y|z>_out_of_tolerance" (the first of them in
// that order; the message lists all); error with "board_not_found", "too_few_features",
// "board_seen_from_behind", "residual_too_high", "uncertainty_too_high" or a PnP outcome
// ("collinear_features", "no_initial_pose", "did_not_converge").

#include <Eigen/Core>
#include <array>
#include <span>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "detectors/core/pose.h"
#include "detectors/detection.h"
#include "station/camera/camera_model.h"
#include "station/model/car_model.h"
#include "station/model/station_layout.h"
#include "station/solvers/mounting.h"
#include "station/solvers/pnp.h"
#include "station/solvers/seed_formulas.h"

namespace linecal {

// One board as the camera saw it in one frame: the detector's features (image position and
// board-frame position, metres).
struct BoardObservation {
  std::string board_id;  // a board of the station layout
  std::vector<DetectedFeature> features;
};

struct RangingCheck {
  double true_distance_m = 0;      // a ground point this far ahead of the camera
  double measured_distance_m = 0;  // what the flat-ground formula D = h fy / (v - vp_v) gives
};

struct CameraCalibrationOptions {
  PnpOptions pnp;
  // Fewer features give error too_few_features: 8 over-determine the 6 pose unknowns enough
  // for the residual test to catch a wrong correspondence. [4, 10000].
  int min_features = 8;
  // A residual RMS above this gives error residual_too_high: detectors reach ~0.1 px, so 1 px
  // means a wrong board model, a moved board or a bad correspondence. (0, 100].
  double max_residual_rms_px = 1.0;
  // A 1-sigma above this fraction of a component's tolerance gives error
  // uncertainty_too_high: at 1/3 the 3-sigma band fits inside the tolerance. (0, 10].
  double max_sigma_fraction_of_tolerance = 1.0 / 3.0;
  // Ground distances ahead of the camera for the ranging check, metres.
  std::vector<double> ranging_distances_m = {5, 10, 20, 50};

  // OK or InvalidArgument naming the first bad field. O(1).
  absl::Status Validate() const;
};

struct CameraCalibrationResult {
  Verdict verdict = Verdict::kError;
  std::string reason;   // a code, empty on pass
  std::string message;  // for a person
  bool solved = false;  // the pose below is meaningful
  MountingEstimate mounting;
  double residual_rms_px = 0;
  int features_used = 0;
  int boards_used = 0;
  // When solved: each observed board's reprojection RMS (pixels) over its detections in every
  // frame, in the order the boards were first observed.
  std::vector<BoardResidual> board_residuals;
  // The vanishing point of the car's longitudinal axis in the undistorted image (K of the
  // intrinsics), pixels: of +x_car for a camera looking forward, of -x_car for one looking
  // backward (CarAxisAlong); side cameras have none (vanishing_point_valid = false).
  Eigen::Vector2d vanishing_point_px = Eigen::Vector2d::Zero();
  bool vanishing_point_valid = false;
  // H_image_ground = K [r1 r2 t] of T_camera_car: the ground plane z_car = 0 ((x, y) in
  // metres) to the undistorted image (the pinhole K = fx, fy, cx, cy of the intrinsics; lens
  // distortion removed). Scaled to H(2, 2) = 1.
  Eigen::Matrix3d ground_homography = Eigen::Matrix3d::Identity();
  std::vector<RangingCheck> ranging;
  // Method (b), the board method of seed_formulas.h, from the wide chessboard with the most
  // features (all frames pooled) and the solved camera position, for a camera looking along
  // the car; board_method.valid = false with a reason otherwise ("chessboard_not_seen" or a
  // reason of SolveBoardMethod).
  BoardMethodResult board_method;
  // When board_method is valid: |vp_b - vp_a| and, per ranging distance, how far the two
  // ground homographies disagree on the ground (GroundDisagreement with (a) as reference),
  // for (b)'s levelled homography and for the toolbox formula's.
  double vanishing_point_disagreement_px = 0;
  std::vector<double> ground_disagreement;
  std::vector<double> toolbox_ground_disagreement;
  // Roll from the corner lines of the vertical board with the most features, the car axis
  // taken from the pose; valid = false with a reason ("vertical_board_not_seen" or one of
  // RollFromVerticalBoard) otherwise. Its difference from the pose's roll is
  // vertical_roll.roll_rad - mounting.angles.roll.
  VerticalBoardRoll vertical_roll;
};

// Calibrates `sensor` (a camera of the car model, with intrinsics) from its observations.
// Errors (InvalidArgument): not a camera, invalid intrinsics or options, an observation of a
// board that is not in `station`. Everything else is an outcome in the result. Cost: one PnP
// solve over all features (about 1 ms for 150).
absl::StatusOr<CameraCalibrationResult> CalibrateCamera(
    const SensorModel& sensor, const StationLayout& station, const Rigid3d& T_station_car,
    std::span<const BoardObservation> observations, const CameraCalibrationOptions& options = {});

// +1 when the camera's optical axis is within 45 degrees of +x_car (it looks forward), -1
// within 45 degrees of -x_car (backward), 0 otherwise (sideways). O(1).
int CarAxisAlong(const Rigid3d& T_camera_car);

// The ground points at `distances_m` straight ahead of the camera (along ±x_car, the way it
// looks (CarAxisAlong), from the camera's footprint) imaged through T_camera_car and the full lens
// model, and the distance the flat-ground formula of the reference toolbox recovers from each
// pixel: D_lon = h fy / (v_u - vp_v), with h the camera height, v_u the undistorted row and vp the
// vanishing point. Its error measures how well (h, vp) stand in for the full extrinsic. A distance
// whose point the camera cannot see, or any distance for a side camera, gives measured_distance_m =
// NaN. O(n).
std::vector<RangingCheck> RangingCheckOf(const CameraModel& camera, const Rigid3d& T_camera_car,
                                         const Eigen::Vector2d& vanishing_point_px,
                                         std::span<const double> distances_m);

// The vanishing point of the car's longitudinal axis in the undistorted image (K of
// `intrinsics`): of +x_car for a camera looking forward, of -x_car for one looking backward
// (CarAxisAlong); false for a side camera. O(1).
bool CarAxisVanishingPoint(const CameraIntrinsics& intrinsics, const Rigid3d& T_camera_car,
                           Eigen::Vector2d* vanishing_point_px);

// H_image_ground = K [r1 r2 t] of T_camera_car: the ground plane z_car = 0 ((x, y) in metres)
// to the undistorted image of K, scaled to H(2, 2) = 1. O(1).
Eigen::Matrix3d GroundHomography(const CameraIntrinsics& intrinsics, const Rigid3d& T_camera_car);

}  // namespace linecal
