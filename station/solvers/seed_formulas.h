#pragma once
// The reference toolbox's "seed formulas" for a camera looking along the car: the board
// method for the vanishing point and the ground homography (method (b) of docs/solvers.md,
// cross-checking method (a), which derives both from the solved extrinsic), the flat-ground
// ranging formula, and the roll from the vertical board's corner lines. One implementation,
// for the station's solver and the after-sale tool.
//
// Frames (docs/conventions.md): car x forward, y left, z up, origin on the ground; board x right
// and y up as seen facing the print, z out of the print; camera x right, y down, z forward.
// Every pixel here is in the *undistorted* image of K = (fx, fy, cx, cy) of the intrinsics:
// observed pixels are unprojected through the full lens model and projected by K, as
// method (a) does.
//
// The board method. H is the homography from the wide chessboard's plane (board frame,
// metres) to the undistorted image, fitted from its corners (the toolbox writes the
// image-to-board map and applies its inverse: the same matrix). The camera centre c (car
// frame) is given: measured in a workshop, the PnP's position in the station.
//   vanishing point  vp = H (x_f, y_f, 1): (x_f, y_f) is where the line through c along the
//                    car axis (+x_car for a camera looking forward, -x_car backward) meets
//                    the board plane, in board coordinates. Every point of that line images
//                    at the axis's vanishing point. For a board standing upright with its
//                    face across the car axis (board x = -y_car, y = z_car, as a board in
//                    front of the car stands) this is the toolbox's
//                    (x_f, y_f) = (-lateral_offset, camera_height - board_height) with
//                    lateral_offset = c_y - b_y (positive when the camera is left of the
//                    board centre b) and the heights c_z, b_z above the ground. The general
//                    intersection is used because the aligner's thrust angle turns the car
//                    axis off the board normal: 0.2 deg moves the literal formula's point
//                    by D tan(0.2 deg), 18 mm at 5 m, 5 px for the front camera.
//   ground points    A, B: the points of the board plane on the ground (z_car = 0) straight
//                    below the centres of the left and right pattern groups (board x < 0
//                    and > 0), imaged by H; A', B': the midpoints of A-vp and B-vp.
//   ranging          the toolbox's D_lon = h fy / (v - vp_v), D_lat = D_lon (vp_u - u) / fx
//                    (h = c_z) for each of A, B, A', B', i.e. the ground point
//                    (c_x + s D_lon, c_y + s D_lat) with s = +1 looking forward, -1 backward;
//                    and the same distances measured in the levelled frame (below).
//   homography       the ground plane (x, y of the car frame) to the undistorted image,
//                    through those four points, scaled to H(2, 2) = 1.
// The toolbox's ranging formula is exact only for a camera whose optical axis is level and
// along the car axis: it takes the angle below the horizon as tan(a) - tan(-pitch) instead of
// tan(a + pitch), so for a camera pitched down by p a point at depression angle d reads
// 1 / (1 - tan(d - p) tan(p)) long (0.7% at 5 m for the reference front camera, 1.5 deg down
// at 1.35 m; 1.1% at 3 deg, the pitch tolerance x 1.5), and D_lat does the same with
// the yaw. Its four points and homography (toolbox_*) inherit that. The levelled frame
// removes it with what the board already gives: the horizon is the line through vp and
// H (1, 0, 0) (the image of the board's x axis, horizontal on an upright board), the ground
// normal N = K^T horizon, F the viewing direction K^-1 vp made perpendicular to N, L = N x F;
// a pixel's ray r meets the ground at P = h r / (-N.r), and (D_lon, D_lat) = (P.F, P.L). For
// a level camera looking along the car both are the toolbox's formula; ground_points_car_m
// and ground_homography are the levelled ones.
//
// Roll from the vertical board. The board's corner columns (board x = const) are vertical
// lines of the car frame; their images all pass through the image V of the vertical
// direction, and V is perpendicular to the car axis direction F. With R_car_camera =
// Rz(yaw) Ry(pitch) Rx(roll) R_base, V ~ (-sin roll, -cos roll, -tan pitch) in the camera
// frame, so roll = atan2(-V_x, -V_y) whatever yaw and pitch: the slopes of the lines, read
// with the perspective of the lines' position in the image taken into account (a line at the
// image's side tilts by its distance from the centre times tan(pitch) / f even at zero roll:
// 0.8 deg for the reference front camera's vertical board, 750 px off centre). V is the
// direction perpendicular to F closest to every line (a 2x2 eigenproblem, each line
// weighted by its length and the square root of its corner count).

#include <Eigen/Core>
#include <span>
#include <string>
#include <vector>

#include "detectors/boards/board.h"
#include "detectors/core/pose.h"
#include "detectors/detection.h"
#include "station/camera/camera_model.h"

namespace linecal {

// The pinhole matrix K of the intrinsics (fx, fy, cx, cy; no distortion). O(1).
Eigen::Matrix3d PinholeMatrix(const CameraIntrinsics& intrinsics);

// The undistorted pixel K ray / ray_z of an observed pixel; false when the pixel is outside
// the lens model or its ray does not point forward (z <= 0). O(1) (a lens unprojection).
bool UndistortedPixel(const CameraModel& camera, const Eigen::Vector2d& uv_px,
                      Eigen::Vector2d* undistorted_px);

// The flat-ground ranging formula of the reference toolbox for an undistorted pixel:
// (D_lon, D_lat) = (h fy / (v - vp_v), D_lon (vp_u - u) / fx), metres ahead of and to the left
// of the camera's footprint as the camera sees it. NaN for a pixel on or above the horizon
// (v <= vp_v). O(1).
Eigen::Vector2d FlatGroundRange(const CameraIntrinsics& intrinsics,
                                const Eigen::Vector2d& vanishing_point_px, double camera_height_m,
                                const Eigen::Vector2d& undistorted_px);

struct BoardMethodResult {
  bool valid = false;
  // Empty when valid, else one of "not_a_chessboard", "not_looking_along_car",
  // "too_few_features", "homography_failed", "axis_parallel_to_board", "board_behind_camera",
  // "board_not_upright", "ground_point_above_horizon", "ground_homography_failed".
  std::string reason;
  std::string message;  // for a person
  Eigen::Matrix3d H_image_board =
      Eigen::Matrix3d::Identity();  // board plane (m) -> undistorted image
  double homography_rms_px = 0;
  Eigen::Vector2d board_point_ahead_m = Eigen::Vector2d::Zero();  // (x_f, y_f) above
  Eigen::Vector2d vanishing_point_px = Eigen::Vector2d::Zero();
  // A, B, A', B' in the undistorted image and their ground positions (car frame x, y) by the
  // ranging formula.
  std::vector<Eigen::Vector2d> ground_points_px;
  std::vector<Eigen::Vector2d> ground_points_car_m;  // levelled frame
  Eigen::Matrix3d ground_homography =
      Eigen::Matrix3d::Identity();  // ground (x, y) -> image, levelled
  // The same by the toolbox's small-angle ranging formula (biased when pitched, above).
  std::vector<Eigen::Vector2d> toolbox_ground_points_car_m;
  Eigen::Matrix3d toolbox_ground_homography = Eigen::Matrix3d::Identity();
};

// The board method for the wide chessboard `board` (type kChessboard) at T_car_board, seen
// by `camera` centred at p_car_camera, looking along +x_car (along = +1) or -x_car (-1),
// from the chessboard's detected `features` (several frames may be pooled). Needs 4 features
// in each pattern group. Refusals are results with a reason (above), never errors. O(n).
BoardMethodResult SolveBoardMethod(const CameraModel& camera, const Board& board,
                                   const Rigid3d& T_car_board, const Eigen::Vector3d& p_car_camera,
                                   int along, std::span<const DetectedFeature> features);

// How far two ground homographies (ground (x, y) -> undistorted image) disagree on the
// ground: for each distance d, the ground point d ahead of the camera centred at p_car_camera
// (along +-x_car as `along` says) imaged by H_reference and mapped back to the ground by
// H_other, |moved| / d. NaN for a point behind the camera (its image through H_reference
// has w <= 0). O(n).
std::vector<double> GroundDisagreement(const Eigen::Matrix3d& H_reference,
                                       const Eigen::Matrix3d& H_other,
                                       const Eigen::Vector3d& p_car_camera, int along,
                                       std::span<const double> distances_m);

struct VerticalBoardRoll {
  bool valid = false;
  // Empty when valid, else "not_a_vertical_board", "board_not_upright", "too_few_lines",
  // "degenerate_lines".
  std::string reason;
  std::string message;
  double roll_rad = 0;  // per docs/conventions.md
  int lines_used = 0;   // corner columns with at least 3 corners
};

// The roll of `camera` from the corner columns of the vertical board `board` (type
// kVertical) at T_car_board, given F, the car axis +x_car in the camera frame (from the pose,
// or K^-1 of a vanishing point). Needs 2 columns of 3 corners; the board's y axis must be
// vertical in the car frame within 1e-4 rad (its columns are the vertical lines). O(n).
VerticalBoardRoll RollFromVerticalBoard(const CameraModel& camera, const Board& board,
                                        const Rigid3d& T_car_board,
                                        const Eigen::Vector3d& car_x_in_camera,
                                        std::span<const DetectedFeature> features);

}  // namespace linecal
