#pragma once
// The documents of the after-sale calibration from lane lines (docs/aftersale.md): its input
// (the JSON that `linecal aftersale --input` reads and the console's POST /api/aftersale
// sends), the result as JSON (`linecal aftersale --json`) and the three export files of the
// reference toolbox's layout (`--export`). One implementation for the command and the daemon,
// so that both give the same numbers and the same bytes for the same input.
//
// Units and frames as lane_calibration.h: image points are distorted pixels with the centre of
// the top-left pixel at (0, 0); metres; the input's angles in degrees.

#include <Eigen/Core>
#include <array>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "station/camera/camera_model.h"
#include "station/io/json_reader.h"
#include "station/solvers/lane_calibration.h"

namespace linecal {

// The input as given, before the image size is known; unset optionals are missing values
// (AftersaleSolverInput names them).
struct AftersaleRequest {
  std::string name = "front_camera";
  std::string image;  // as written in the document (the command resolves it)
  CameraModelType model = CameraModelType::kPinhole;
  std::optional<double> fx, fy, cx, cy;
  std::vector<double> distortion;  // pinhole k1 k2 p1 p2 [k3]; fisheye k1 k2 k3 k4
  std::optional<double> camera_height_m;
  double longitudinal_offset_m = 0;
  double lateral_offset_m = 0;
  bool looking_backward = false;
  std::vector<std::vector<Eigen::Vector2d>> lanes_px;
  std::optional<std::array<Eigen::Vector2d, 2>> roll_line_px;
  double roll_deg = 0;
  std::optional<Eigen::Vector2d> marked_point_px;
  std::optional<double> measured_distance_m;
  double tolerance_percent = 1.0;
};

// Reads the input document at `root` (docs/aftersale.md, "Input": name, image, intrinsics,
// camera_height_m, longitudinal_offset_m, lateral_offset_m, looking_backward, lanes or
// markers, roll_line, roll_deg, marked_point, tolerance_percent) into `r`, overriding what it
// holds. Errors (InvalidArgument) name the field through `root` ("in.json: lanes[0][1]: must
// be [u, v], two numbers"), including unknown keys. O(size of the document).
absl::Status ReadAftersaleInput(const JsonField& root, AftersaleRequest* r);

// Four markers, left near, left far, right near, right far, as two lines parallel to the car.
// InvalidArgument "<what>: 4 markers needed, got N".
absl::StatusOr<std::vector<std::vector<Eigen::Vector2d>>> LanesOfMarkers(
    const std::vector<Eigen::Vector2d>& markers, const std::string& what);

// The input document's camera part for a camera of these intrinsics at xyz_m (car frame):
// name, intrinsics (model, fx, fy, cx, cy, distortion), camera_height_m = z,
// longitudinal_offset_m = x, lateral_offset_m = y, looking_backward, tolerance_percent 1.
// What `linecal sim lanes` writes and the console starts from for a car model's camera.
nlohmann::json AftersaleCameraInput(const std::string& name, const CameraIntrinsics& k,
                                    const Eigen::Vector3d& xyz_m, bool looking_backward);

// The solver's input for an image of width x height pixels: cx and cy default to the image
// centre ((w - 1) / 2, (h - 1) / 2). InvalidArgument for a missing value, named with its
// field and the command's flag ("camera_height_m: missing (--camera-height-m or the input
// file's camera_height_m)"), or a distortion of the wrong length. The solver checks the rest.
absl::StatusOr<LaneCalibrationInput> AftersaleSolverInput(const AftersaleRequest& r, int width,
                                                          int height);

// The result as `linecal aftersale --json` prints it, without the files it names (image,
// overlay_png, birdseye_png, export): name, image_size, vanishing_point_px,
// vanishing_point_residual_px, lane_fit_rms_px, roll_source, ypr_deg, T_car_camera,
// ground_homography, h_matrix, flat_formula and, with a marked point, distance_check.
nlohmann::json AftersaleResultJson(const std::string& name, const LaneCalibrationInput& in,
                                   const LaneCalibrationResult& r);

// H_ground_image: the undistorted image to the ground (x, y) in metres, scaled to H(2, 2) = 1,
// the direction the reference toolbox's h_matrix maps.
Eigen::Matrix3d AftersaleImageToGround(const LaneCalibrationResult& r);

// The three export files of `--export` (docs/aftersale.md, "Export"), file name and document:
// <name>-calibration.json, <name>-intrinsic.json, <name>-to-car_center-extrinsic.json. Write
// each with WriteJsonFile, or serve JsonFileText of it: the same bytes.
std::vector<std::pair<std::string, nlohmann::json>> AftersaleExportFiles(
    const std::string& name, const LaneCalibrationInput& in, const LaneCalibrationResult& r);

}  // namespace linecal
