#pragma once
// Lane scenes for the after-sale calibration (docs/simulator.md, "Lane scenes"): white lines
// painted on a grey ground in front of a car, seen by one camera at a known mounting, with the
// exact image points a technician would mark and the true vanishing point.
//
// The painted lines are rectangles of the camera renderer (RenderCameraFrame) lying on the
// ground of the car frame (the station frame is the car frame here): two lane lines parallel
// to x_car, optionally a roll line perpendicular to the car (across the lane, both ends at the
// same distance) and four square markers on two lines parallel to the car. Distances are
// measured ahead of the camera (along +x_car, or -x_car for a camera looking backward) from
// the point on the ground under it.

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <vector>

#include "absl/status/statusor.h"
#include "detectors/core/pose.h"
#include "station/camera/camera_model.h"
#include "station/sim/camera_render.h"

namespace linecal {

struct LaneSceneOptions {
  // Lateral distance between the centre lines of the two lane lines, and the lane's centre
  // (y_car), metres. Width (0, 20], centre finite.
  double lane_width_m = 3.5;
  double lane_centre_y_m = 0.0;
  double line_width_m = 0.15;  // painted width of every line, (0, 1]
  // The lane lines run from this near to this far distance, 0 <= near < far <= 1000 m.
  double line_near_m = 2.0;
  double line_far_m = 80.0;
  // The points marked on each lane line (its centre line), at these distances; at least 2.
  std::vector<double> point_distances_m = {6.0, 25.0};
  // The roll line across the lane at this distance (0 = none), from one lane line's centre to
  // the other's; its end points are the marked roll-line points. [0, 1000].
  double roll_line_distance_m = 8.0;
  // Four square markers, side marker_size_m, at these two distances on the lane lines' centre
  // lines (both 0 = none). The markers are painted in addition to the lines when
  // paint_lane_lines is on.
  std::array<double, 2> marker_distances_m = {0.0, 0.0};
  double marker_size_m = 0.3;  // (0, 2]
  bool paint_lane_lines = true;
  // The marked point for the ranging check, on the lane's centre line at this distance (0 =
  // none). [0, 1000].
  double marked_point_distance_m = 15.0;
  // Gaussian noise added to every listed image point, pixels, [0, 10].
  double point_noise_px = 0.0;
  double paint_reflectance = 0.8;   // the painted lines, [0, 1]
  double ground_reflectance = 0.2;  // the road, [0, 1]
  CameraRenderOptions render;
  // Off: only the points and the truth, no image (LaneScene::frame stays empty), for
  // evaluations that need thousands of scenes.
  bool render_image = true;

  // OK, or InvalidArgument naming the first bad field. O(1).
  absl::Status Validate() const;
};

struct LaneScene {
  CameraFrame frame;  // the rendered image (empty without render_image)
  // Per lane line (left, i.e. +y, first): the image points at point_distances_m, distorted
  // pixels, with point_noise_px.
  std::vector<std::vector<Eigen::Vector2d>> lanes_px;
  bool has_roll_line = false;
  std::array<Eigen::Vector2d, 2> roll_line_px = {Eigen::Vector2d::Zero(), Eigen::Vector2d::Zero()};
  // The marker centres: left near, left far, right near, right far (empty without markers).
  std::vector<Eigen::Vector2d> markers_px;
  bool has_marked_point = false;
  Eigen::Vector2d marked_point_px = Eigen::Vector2d::Zero();
  // The truth: the vanishing point of the car's axis in the undistorted image
  // (CarAxisVanishingPoint) and the mounting.
  Eigen::Vector2d vanishing_point_px = Eigen::Vector2d::Zero();
  YawPitchRoll angles;
};

// Renders the lane scene of `camera` mounted at T_car_camera. Deterministic for `seed` (noise
// of the image and of the points). Errors (InvalidArgument): invalid options, a camera that
// looks sideways (no vanishing point of the car's axis), a listed point the camera does not
// see inside its image. Cost: one RenderCameraFrame (about 0.2 s for 1920 x 1080), or a few
// microseconds without render_image.
absl::StatusOr<LaneScene> RenderLaneScene(const CameraModel& camera, const Rigid3d& T_car_camera,
                                          const LaneSceneOptions& options, std::uint64_t seed);

}  // namespace linecal
