#include "tools/linecal/car_camera.h"

#include "absl/strings/str_cat.h"

namespace linecal::tools {

absl::StatusOr<SensorModel> ReadCarCamera(const std::string& car_path, const std::string& name) {
  absl::StatusOr<CarModel> car = ReadCarModel(car_path);
  if (!car.ok()) return absl::InvalidArgumentError(car.status().message());
  const SensorModel* sensor = car->FindSensor(name);
  if (sensor == nullptr || sensor->kind != SensorKind::kCamera || !sensor->intrinsics) {
    return absl::InvalidArgumentError(
        absl::StrCat("--camera: '", name, "' is not a camera of ", car_path));
  }
  return *sensor;
}

}  // namespace linecal::tools
