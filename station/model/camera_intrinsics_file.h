#pragma once
// A camera's intrinsics from the calibration files that people have (docs/interfaces.md,
// "Camera intrinsics files"), as linecal's CameraIntrinsics:
//
//   - linecal's car model (JSON, docs/station-and-car.md): the camera sensor named;
//   - OpenCV's cv::FileStorage, YAML (`%YAML:1.0`, `!!opencv-matrix`) or JSON: the keys
//     image_width, image_height, camera_matrix and distortion_coefficients that OpenCV's
//     calibration samples write, each matrix a map of rows, cols, (dt) and data;
//   - ROS camera_info YAML (camera_calibration_parsers): the same keys plus distortion_model
//     and camera_name;
//   - Kalibr camchain YAML: cam0, cam1, ... each with camera_model, intrinsics [fu, fv, pu, pv],
//     distortion_model, distortion_coeffs and resolution [width, height].
//
// The format is told by the keys of the top-level map: `sensors` is a car model, `camN` a
// Kalibr camchain, `camera_matrix` an OpenCV or ROS file. The projection model is told by
// distortion_model (OpenCV and ROS: absent, plumb_bob, rational_polynomial or radtan for the
// pinhole; equidistant, fisheye or kannala_brandt for the fisheye; Kalibr: radtan, none or
// equidistant on camera_model pinhole) or, in OpenCV files, by fisheye_model (0 or 1, as
// OpenCV's camera calibration tutorial writes it); neither key means the pinhole. The pinhole takes
// OpenCV's coefficient vectors of 0, 4, 5, 8, 12 or 14 values (k1 k2 p1 p2 k3 k4 k5 k6 s1 s2 s3 s4
// τx τy) as long as everything after k3 is 0, since linecal's pinhole has no rational, thin-prism
// or tilt terms; the fisheye takes exactly 4 (k1..k4). A camera matrix must be 3 x 3 without skew.
// All these formats put the centre of the top-left pixel at (0, 0), as linecal does, so the numbers
// are taken as they are.
//
// Errors (InvalidArgument) name the file and the key, and the value when it is wrong:
//   "cal.yaml: camera_matrix.data: 8 numbers for a 3 x 3 matrix"
//   "cal.yaml: distortion_model: 'omni' is not plumb_bob, rational_polynomial, ..."

#include <string>

#include "absl/status/statusor.h"
#include "station/camera/camera_model.h"

namespace linecal {

// Reads the camera `camera_name` of the file at `path` (any size up to ReadTextFile's limit).
// A car model or Kalibr camchain with several cameras needs the name (the error lists the
// names); with one camera, or for OpenCV and ROS files, it may be empty. A ROS file checks a
// given name against its camera_name; an OpenCV file has no name and refuses one. The result
// passed CameraIntrinsics::Validate. Cost: reading and parsing the file.
absl::StatusOr<CameraIntrinsics> ReadCameraIntrinsicsFile(const std::string& path,
                                                          const std::string& camera_name);

// The same for a file's text; `source` names it in messages and resolves the car model's
// relative paths.
absl::StatusOr<CameraIntrinsics> ParseCameraIntrinsics(const std::string& text,
                                                       const std::string& source,
                                                       const std::string& camera_name);

}  // namespace linecal
