#pragma once
// The results document of a calibration cycle (docs/interfaces.md, "Results"): what
// `linecal calibrate --json` prints, the daemon keeps per cycle and the evaluations read.

#include <nlohmann/json.hpp>

#include "station/capture/capture.h"
#include "station/pipeline/capture_calibration.h"

namespace linecal {

// The results document of docs/interfaces.md ("Results"): per sensor name, kind, verdict, reason,
// message, T_car_sensor (4x4 row-major), yaw/pitch/roll (deg) and x/y/z (m), their deviation
// and 1-sigma, residual RMS, features used; cameras also the vanishing point, the ground
// homography and the ranging check, and (docs/solvers.md) "board_method" (method (b) and its
// disagreement) and "roll_from_vertical_board"; overall verdict, VIN, car model and timings.
nlohmann::json CycleCalibrationToJson(const Capture& capture, const CycleCalibration& cycle);

}  // namespace linecal
