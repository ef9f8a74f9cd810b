#pragma once
// After-sale camera calibration from lane lines (docs/aftersale.md): a technician marks, in
// one image of the car's camera, points on two or more straight lines painted on the ground
// parallel to the car (lane lines, or pairs of markers laid out parallel to the car) and
// optionally the two ends of a roll line (a ground line perpendicular to the car, both ends
// at the same measured distance from it). With the camera height, its offsets and the
// intrinsics this gives:
//   - the vanishing point of the car's axis: each line fitted to its undistorted points
//     (total least squares), the point nearest to all lines in least squares;
//   - roll from the roll line, else an assumed roll;
//   - pitch and yaw from the vanishing point's ray given that roll;
//   - the ground homography of that pose (GroundHomography of camera_calibration.h: the exact
//     ray-ground geometry with the roll, not the flat formula), ground points of pixels, and
//     the flat-ground formula's reading of that pose (RangingCheckOf);
//   - with a marked point and its measured distance: the ranging error, pass or fail.
//
// Frames and units per docs/conventions.md: car frame (x forward, y left, z up, origin on the
// ground under the rear axle), R_car_camera = Rz(yaw) Ry(pitch) Rx(roll) CameraBaseRotation().
// Image points are distorted pixels as stored in the image; the vanishing point and the
// homography are in the undistorted image of K = (fx, fy, cx, cy).

#include <Eigen/Core>
#include <array>
#include <optional>
#include <vector>

#include "absl/status/statusor.h"
#include "detectors/core/pose.h"
#include "station/camera/camera_model.h"
#include "station/solvers/camera_calibration.h"

namespace linecal {

struct LaneMarkedPoint {
  Eigen::Vector2d uv_px = Eigen::Vector2d::Zero();
  // Measured longitudinal distance (along x_car) from the point on the ground under the camera
  // to the marked point, metres, > 0.
  double measured_distance_m = 0;
};

struct LaneCalibrationInput {
  CameraIntrinsics intrinsics;
  // Lines on the ground parallel to x_car, each with at least 2 image points (distorted
  // pixels); at least 2 lines.
  std::vector<std::vector<Eigen::Vector2d>> lanes_px;
  // The two ends of the roll line, when painted.
  std::optional<std::array<Eigen::Vector2d, 2>> roll_line_px;
  // The roll assumed without a roll line, radians, |roll| <= 45 degrees.
  double assumed_roll_rad = 0;
  // The camera looks backward (its lanes meet at the vanishing point of -x_car).
  bool looking_backward = false;
  // The camera's optical centre in the car frame: height above the ground (0, 10] m,
  // longitudinal (x) and lateral (y) offset from the car origin, finite.
  double camera_height_m = 0;
  double longitudinal_offset_m = 0;
  double lateral_offset_m = 0;
  std::optional<LaneMarkedPoint> marked_point;
  // Pass when the ranging error of the marked point is within this percentage, (0, 100].
  double tolerance_percent = 1.0;
  // Distances ahead of the camera for the flat-formula reading (RangingCheckOf), (0, 1e4) m.
  std::vector<double> ranging_distances_m = {5, 10, 20, 30};
};

struct LaneDistanceCheck {
  double measured_distance_m = 0;
  double computed_distance_m = 0;  // through the ground homography
  double error_percent = 0;        // 100 (computed - measured) / measured
  bool pass = false;
};

struct LaneCalibrationResult {
  Eigen::Vector2d vanishing_point_px = Eigen::Vector2d::Zero();
  // RMS distance of the vanishing point from the fitted lines (0 for two lines), pixels.
  double vanishing_point_residual_px = 0;
  // Per line: RMS distance of its undistorted points from its fitted line, pixels (0 for two
  // points).
  std::vector<double> lane_fit_rms_px;
  bool roll_from_line = false;
  YawPitchRoll angles;
  Rigid3d T_car_camera;
  // H_image_ground (GroundHomography): ground (x, y) metres to the undistorted image.
  Eigen::Matrix3d ground_homography = Eigen::Matrix3d::Identity();
  // The flat-ground formula D = h fy / (v - vp_v) on this pose (RangingCheckOf).
  std::vector<RangingCheck> flat_formula;
  std::optional<LaneDistanceCheck> distance_check;
};

// Calibrates the camera from `input`. Errors (InvalidArgument, the message naming the
// problem and the field): bad intrinsics or values ("camera_height_m = 0: must be in (0, 10]"),
// too few lines or points, coincident points, a point without a ray in the lens model,
// "parallel lines" (the lines meet at infinity in the image, less than 0.5 degrees apart), a
// roll line through the vanishing point, a lane, roll-line or marked point "above the
// horizon" of the result (it cannot lie on the ground). O(number of points).
absl::StatusOr<LaneCalibrationResult> CalibrateFromLanes(const LaneCalibrationInput& input);

// The ground point (x, y) in the car frame that the distorted pixel uv_px sees, through the
// ground homography of T_camera_car (GroundHomography); false when the pixel has no ray or is
// not below the horizon (its ray does not go down to the ground). O(1).
bool GroundPointOfPixel(const CameraModel& camera, const Rigid3d& T_camera_car,
                        const Eigen::Vector2d& uv_px, Eigen::Vector2d* p_ground);

// The ranging error of an estimated mounting at ground point p_ground (car frame, z = 0): the
// point imaged through the true mounting and the lens, taken back to the ground through the
// estimate (GroundPointOfPixel), the distance between the two over the point's horizontal
// distance from the camera's footprint. NaN when the true camera does not see the point or the
// estimate puts its pixel above the horizon. For evaluations and tests. O(1).
double RelativeRangingError(const CameraModel& camera, const Rigid3d& T_car_camera_true,
                            const Rigid3d& T_car_camera_estimate, const Eigen::Vector2d& p_ground);

}  // namespace linecal
