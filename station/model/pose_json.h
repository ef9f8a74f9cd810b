#pragma once
// Poses in linecal's JSON files (station layouts, car models, captures, results).
//
// A pose is written either as mounting angles and a position, the form people edit,
//   {"xyz_m": [x, y, z], "ypr_deg": [yaw, pitch, roll]}
// meaning R = Rz(yaw) * Ry(pitch) * Rx(roll) * R_base (docs/conventions.md) with the R_base of what
// is being placed (camera, board, ...), or as a full 4x4 row-major matrix,
//   {"matrix": [r00, r01, r02, tx, r10, ..., 0, 0, 0, 1]}
// whose rotation part must be orthonormal (to 1e-6) with determinant +1.

#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include "absl/status/statusor.h"
#include "detectors/core/pose.h"
#include "station/io/json_reader.h"

namespace linecal {

// Reads the pose at `parent.key`. Errors name the field.
absl::StatusOr<Rigid3d> ReadPose(const JsonField& parent, const std::string& key,
                                 const Eigen::Matrix3d& r_base);

// The angle form (xyz_m, ypr_deg) plus the exact matrix, so files stay readable and lossless.
nlohmann::json PoseToJson(const Rigid3d& pose, const Eigen::Matrix3d& r_base);

// The 4x4 row-major matrix as a flat JSON array of 16 numbers.
nlohmann::json MatrixToJson(const Eigen::Matrix4d& m);

// R_base of a calibration board in the station: a board at yaw = pitch = roll = 0 stands
// upright and faces a car that looks along +x, i.e. its printed face looks along -x_station:
// z_board = -x_station, y_board = +z_station (up), x_board = -y_station (the right-hand side of
// a person at the car looking at the print).
Eigen::Matrix3d BoardBaseRotation();

}  // namespace linecal
