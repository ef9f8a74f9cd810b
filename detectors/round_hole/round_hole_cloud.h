#pragma once
// The LiDAR side of the round-hole board (docs/boards.md section 6): finds the board in point
// clouds of a spinning LiDAR, near where it is expected, and measures its pose and its five
// hole centres. The method (docs/lidar-radar.md, "Round-hole board in point clouds"):
//
//  1. Region of interest: the points within the page plus a margin, and within a depth
//     band, of the expected board pose.
//  2. Plane: an iteratively reweighted least-squares fit (Tukey biweight) of the ranges,
//     seeded by the expected plane, over every frame's points together.
//  3. Every in-plane point is moved along its ray onto the plane, which removes the range
//     noise from its in-plane position: what is left is the azimuth step of the rings.
//  4. Along each ring (sorted by azimuth) the runs of points on the plane and the gaps
//     between them give edges: paper -> hole, hole -> paper and the page's sides, each half
//     an azimuth step beyond the last point on paper.
//  5. The in-plane pose (x, y, rotation) is found by a coarse search for the best agreement
//     of the drawing with the points (points on paper, gaps in holes or off the page), then
//     refined by a robust Gauss-Newton fit of all edges of all rings and frames to the five
//     hole circles and the outline together: a hole that one ring crosses is placed by the
//     others through the rigid board.
//  Gaps and ring ends where a ray hit something in front of the board (an occluder) give no
//  edges, nor do rings spanning under a tenth of the page (the board's stand). The pose's
//  covariance models each edge as uniform within half an azimuth step (see pose_covariance).
//
// Frames and units: points and results are in the LiDAR frame (the sensor's own origin,
// rays start there), metres; the board frame is that of detectors/boards/board.h. Pure
// function over non-owning views; no allocation beyond a few copies of the ROI points.
// Rings are taken to spin about the LiDAR z axis (true of every supported model).

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include "detectors/boards/board.h"
#include "detectors/core/pose.h"

namespace linecal {

// One LiDAR return, as the decoders give it (station/sensors/lidar/lidar_point.h, without the
// fields the detector does not use). x, y, z: metres, LiDAR frame; ring: beam index sorted by
// elevation. A frame's points may come in any order.
struct RoundHoleCloudPoint {
  float x = 0.0f;
  float y = 0.0f;
  float z = 0.0f;
  std::uint16_t ring = 0;
};

struct RoundHoleCloudOptions {
  // The region of interest extends this far beyond the page in the board plane, and the
  // depth band this far on either side of the expected plane, metres. It must hold the
  // expected pose's error: 0.3 m is ten times the station's LiDAR mounting tolerance (3 cm,
  // 0.5 degree, i.e. 7 cm at 8 m).
  double roi_margin_m = 0.3;
  double roi_depth_m = 0.3;
  // The fitted normal may differ from the expected one by at most this much, radians
  // (10 degrees: far beyond a mounting tolerance, well short of another surface).
  double max_tilt_rad = 0.1745;
  // The in-plane coarse search covers shifts of the page up to this far from the expected
  // pose, metres, and rotations up to max_in_plane_rotation_rad (about the plane normal).
  double max_in_plane_shift_m = 0.12;
  double max_in_plane_rotation_rad = 0.035;
  // Fewer rings than this crossing the holes (over all holes and frames) cannot place the
  // board along its y axis (docs/acceptance.md: fewer than two rings through a hole).
  int min_rings_through_holes = 2;
  // OK when every field is finite and in range (margins > 0, 0 < max_tilt_rad < pi/2,
  // shifts >= 0, min_rings_through_holes >= 1). O(1).
  bool Valid() const;
};

enum class RoundHoleCloudReason : std::uint8_t {
  kNone = 0,                 // found
  kBadInput,                 // not a round-hole board, invalid options or a non-finite prior
  kBoardNotInRoi,            // (almost) no finite point in the region of interest
  kNoPlane,                  // no plane like the board's in the region (empty, cluttered, tilted)
  kTooFewRingsThroughHoles,  // fewer than min_rings_through_holes rings cross the holes (or
                             // fewer than two rings reach the board at all)
  kFitFailed,                // the edges do not fit the board's outline and holes
};

// "", "bad_input", "board_not_in_roi", "no_plane", "too_few_rings_through_holes",
// "fit_failed".
const char* RoundHoleCloudReasonName(RoundHoleCloudReason reason);

struct RoundHoleHole {
  int id = 0;  // BoardFeature::id of the hole centre (docs/boards.md)
  Eigen::Vector3d p_lidar = Eigen::Vector3d::Zero();  // metres, LiDAR frame
  int rings = 0;  // distinct rings that crossed this hole (over all frames)
};

struct RoundHoleCloudDetection {
  bool found = false;
  RoundHoleCloudReason reason = RoundHoleCloudReason::kBadInput;
  Rigid3d T_lidar_board;             // valid when found
  std::vector<RoundHoleHole> holes;  // the 5 holes in feature order, when found
  // Fit quality, filled as far as the detector got.
  int roi_points = 0;        // finite points in the region of interest
  int plane_inliers = 0;     // points the plane fit kept
  double plane_rms_m = 0.0;  // RMS range residual of the inliers (along their rays)
  // 1-sigma of the board normal's direction (its worse axis) from the plane fit's
  // covariance, radians: the range noise over the points' spread and number.
  double normal_sigma_rad = 0.0;
  int edges = 0;                // ring edges the in-plane fit kept
  double edge_rms_m = 0.0;      // RMS distance of those edges to the outline and circles
  int rings_through_holes = 0;  // distinct rings crossing at least one hole
  // Covariance of the pose error, in the board frame: T_true = T_lidar_board * (R(theta), t)
  // for small (theta_x, theta_y, theta_z [rad], t_x, t_y, t_z [m]), in that order. In-plane
  // (t_x, t_y, theta_z) from the edge fit's Jacobian with each edge uniformly within half an
  // azimuth step along its ring (frames that fired at the same azimuths share those errors),
  // and what an edge shows beyond that repeated in every frame; out of the plane (theta_x,
  // theta_y, t_z) from the plane fit's range residuals. When found.
  Eigen::Matrix<double, 6, 6> pose_covariance = Eigen::Matrix<double, 6, 6>::Zero();
  // 1-sigma of the in-plane position (x, y of the board frame), metres: of pose_covariance.
  Eigen::Vector2d in_plane_sigma_m = Eigen::Vector2d::Zero();
};

// Detects `board` (must be BoardType::kRoundHole, any scale) in `frames`: one or more
// rotations of one LiDAR, with the board still, accumulated together. `T_lidar_board_prior`
// is the expected board pose (e.g. the nominal mounting and the surveyed board), good to the
// ROI margin and the coarse-search ranges of `options`. Non-finite points are skipped.
// Failure: found = false with the reason; never throws, never asserts on the data.
// Cost: linear in the points (a transform per point) plus O(n log n) in the ROI points, and
// the coarse search (about 10^6 PaintAt look-ups): 4-13 ms per frame of a 10-frame VLP-16 or
// Pandar64 accumulation (docs/lidar-radar.md).
RoundHoleCloudDetection DetectRoundHoleBoardInCloud(
    const Board& board, std::span<const std::span<const RoundHoleCloudPoint>> frames,
    const Rigid3d& T_lidar_board_prior, const RoundHoleCloudOptions& options = {});

}  // namespace linecal
