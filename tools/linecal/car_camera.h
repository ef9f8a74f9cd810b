#pragma once
// The camera `name` of the car model file `car_path`, for the commands that take --car and
// --camera (sim lanes, eval aftersale).

#include <string>

#include "absl/status/statusor.h"
#include "station/model/car_model.h"

namespace linecal::tools {

// Errors (InvalidArgument): the car model file's own, or "--camera: 'x' is not a camera of
// <car_path>" for a sensor that is missing, not a camera or without intrinsics.
absl::StatusOr<SensorModel> ReadCarCamera(const std::string& car_path, const std::string& name);

}  // namespace linecal::tools
