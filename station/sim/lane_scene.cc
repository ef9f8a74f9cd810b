#include "station/sim/lane_scene.h"

#include <cmath>
#include <random>
#include <string>

#include "absl/strings/str_cat.h"
#include "station/model/station_layout.h"
#include "station/solvers/camera_calibration.h"

namespace linecal {
namespace {

// The paint lies this far above the ground plane, so that the renderer's nearest hit is the
// paint, not the road under it; 0.1 mm moves a point 30 m ahead of a 1.35 m high camera by
// 2 mm (0.007%), which the listed points (on the ground) neglect.
constexpr double kPaintHeightM = 1e-4;

absl::Status Range(bool ok, const std::string& field, double value, const std::string& range) {
  if (ok) return absl::OkStatus();
  return absl::InvalidArgumentError(absl::StrCat(field, " = ", value, ": must be in ", range));
}

}  // namespace

absl::Status LaneSceneOptions::Validate() const {
  for (const absl::Status& s :
       {Range(lane_width_m > 0 && lane_width_m <= 20, "lane_width_m", lane_width_m, "(0, 20]"),
        Range(std::isfinite(lane_centre_y_m), "lane_centre_y_m", lane_centre_y_m, "finite values"),
        Range(line_width_m > 0 && line_width_m <= 1, "line_width_m", line_width_m, "(0, 1]"),
        Range(line_near_m >= 0 && line_near_m < line_far_m, "line_near_m", line_near_m,
              "[0, line_far_m)"),
        Range(line_far_m <= 1000, "line_far_m", line_far_m, "(line_near_m, 1000]"),
        Range(roll_line_distance_m >= 0 && roll_line_distance_m <= 1000, "roll_line_distance_m",
              roll_line_distance_m, "[0, 1000]"),
        Range(marker_distances_m[0] >= 0 && marker_distances_m[0] <= 1000, "marker_distances_m[0]",
              marker_distances_m[0], "[0, 1000]"),
        Range(marker_distances_m[1] >= 0 && marker_distances_m[1] <= 1000, "marker_distances_m[1]",
              marker_distances_m[1], "[0, 1000]"),
        Range(marker_size_m > 0 && marker_size_m <= 2, "marker_size_m", marker_size_m, "(0, 2]"),
        Range(marked_point_distance_m >= 0 && marked_point_distance_m <= 1000,
              "marked_point_distance_m", marked_point_distance_m, "[0, 1000]"),
        Range(point_noise_px >= 0 && point_noise_px <= 10, "point_noise_px", point_noise_px,
              "[0, 10]"),
        Range(paint_reflectance >= 0 && paint_reflectance <= 1, "paint_reflectance",
              paint_reflectance, "[0, 1]"),
        Range(ground_reflectance >= 0 && ground_reflectance <= 1, "ground_reflectance",
              ground_reflectance, "[0, 1]")}) {
    if (!s.ok()) return s;
  }
  if (point_distances_m.size() < 2) {
    return absl::InvalidArgumentError(absl::StrCat(
        "point_distances_m: at least 2 distances needed, got ", point_distances_m.size()));
  }
  for (double d : point_distances_m) {
    if (!(d > 0 && d <= 1000)) return Range(false, "point_distances_m", d, "(0, 1000]");
  }
  if ((marker_distances_m[0] > 0) != (marker_distances_m[1] > 0)) {
    return absl::InvalidArgumentError("marker_distances_m: both or neither must be > 0");
  }
  if (absl::Status s = render.Validate(); !s.ok())
    return absl::InvalidArgumentError(absl::StrCat("render.", s.message()));
  return absl::OkStatus();
}

absl::StatusOr<LaneScene> RenderLaneScene(const CameraModel& camera, const Rigid3d& T_car_camera,
                                          const LaneSceneOptions& options, std::uint64_t seed) {
  if (absl::Status s = options.Validate(); !s.ok()) return s;
  const Rigid3d T_camera_car = T_car_camera.Inverse();
  LaneScene scene;
  if (!CarAxisVanishingPoint(camera.intrinsics(), T_camera_car, &scene.vanishing_point_px)) {
    return absl::InvalidArgumentError(
        "the camera looks sideways: a lane scene needs a camera looking along the car");
  }
  scene.angles = MountingAngles(T_car_camera.RotationMatrix(), CameraBaseRotation());
  const double along = CarAxisAlong(T_camera_car);
  const Eigen::Vector3d c = T_car_camera.translation();
  const double y_left = options.lane_centre_y_m + options.lane_width_m / 2;
  const double y_right = options.lane_centre_y_m - options.lane_width_m / 2;
  // A ground point `d` ahead of the camera at lateral position y.
  const auto ground = [&](double d, double y) {
    return Eigen::Vector3d(c.x() + along * d, y, 0.0);
  };

  StationLayout layout;
  layout.name = "lane_scene";
  layout.floor_reflectivity = options.ground_reflectance;
  // A painted rectangle centred on ground point p, extent along x_car and y_car.
  const auto paint = [&](const std::string& id, const Eigen::Vector3d& p, double along_x_m,
                         double along_y_m) {
    StationSurface s;
    s.id = id;
    s.T_station_surface = Rigid3d::Translation(Eigen::Vector3d(p.x(), p.y(), kPaintHeightM));
    s.size_m = Eigen::Vector2d(along_x_m, along_y_m);
    s.reflectivity = options.paint_reflectance;
    layout.surfaces.push_back(s);
  };
  const double mid = (options.line_near_m + options.line_far_m) / 2;
  const double length = options.line_far_m - options.line_near_m;
  if (options.paint_lane_lines) {
    paint("lane_left", ground(mid, y_left), length, options.line_width_m);
    paint("lane_right", ground(mid, y_right), length, options.line_width_m);
  }
  scene.has_roll_line = options.roll_line_distance_m > 0;
  if (scene.has_roll_line) {
    paint("roll_line", ground(options.roll_line_distance_m, options.lane_centre_y_m),
          options.line_width_m, options.lane_width_m);
  }
  const bool markers = options.marker_distances_m[0] > 0;
  if (markers) {
    for (double d : options.marker_distances_m) {
      for (double y : {y_left, y_right})
        paint(absl::StrCat("marker_", d, "_", y), ground(d, y), options.marker_size_m,
              options.marker_size_m);
    }
  }
  if (options.render_image) {
    absl::StatusOr<CameraFrame> frame =
        RenderCameraFrame(camera, T_car_camera, layout, options.render, seed);
    if (!frame.ok()) return frame.status();
    scene.frame = *std::move(frame);
  }

  // The points, exact projections plus their own noise stream (the image noise used `seed`).
  std::mt19937_64 rng(seed ^ 0x9e3779b97f4a7c15ULL);
  std::normal_distribution<double> noise(0.0, 1.0);
  absl::Status status = absl::OkStatus();
  const auto image_of = [&](const Eigen::Vector3d& p_car, const std::string& what) {
    Eigen::Vector2d uv = Eigen::Vector2d::Zero();
    if (!camera.Project(T_camera_car * p_car, &uv) || !camera.IsInImage(uv)) {
      if (status.ok()) {
        status = absl::InvalidArgumentError(
            absl::StrCat(what, ": the camera does not see it inside its image"));
      }
      return uv;
    }
    if (options.point_noise_px > 0) {
      const double du = noise(rng);
      const double dv = noise(rng);
      uv += options.point_noise_px * Eigen::Vector2d(du, dv);
    }
    return uv;
  };
  if (options.paint_lane_lines) {
    for (double y : {y_left, y_right}) {
      std::vector<Eigen::Vector2d> lane;
      for (double d : options.point_distances_m)
        lane.push_back(image_of(ground(d, y), absl::StrCat("lane point at ", d, " m")));
      scene.lanes_px.push_back(lane);
    }
  }
  if (scene.has_roll_line) {
    scene.roll_line_px = {
        image_of(ground(options.roll_line_distance_m, y_left), "roll line, left end"),
        image_of(ground(options.roll_line_distance_m, y_right), "roll line, right end")};
  }
  if (markers) {
    for (double y : {y_left, y_right}) {
      for (double d : options.marker_distances_m)
        scene.markers_px.push_back(image_of(ground(d, y), absl::StrCat("marker at ", d, " m")));
    }
  }
  scene.has_marked_point = options.marked_point_distance_m > 0;
  if (scene.has_marked_point) {
    scene.marked_point_px =
        image_of(ground(options.marked_point_distance_m, options.lane_centre_y_m), "marked point");
  }
  if (!status.ok()) return status;
  return scene;
}

}  // namespace linecal
