#pragma once
// The car model: its sensors, their nominal mounting, tolerances and what they calibrate
// against (docs/station-and-car.md documents the file).

#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "absl/status/statusor.h"
#include "detectors/core/pose.h"
#include "station/camera/camera_model.h"
#include "station/sensors/lidar/lidar_format.h"

namespace linecal {

struct StationLayout;

enum class SensorKind { kCamera, kLidar, kRadar };

// "camera", "lidar", "radar".
const char* SensorKindName(SensorKind kind);
// The kind SensorKindName names ("camera", "lidar", "radar"); nullopt for any other word.
std::optional<SensorKind> ParseSensorKind(std::string_view name);

// Largest allowed deviation from the nominal mounting, per axis (symmetric).
struct MountingTolerance {
  double yaw_rad = 0.0;
  double pitch_rad = 0.0;
  double roll_rad = 0.0;
  Eigen::Vector3d xyz_m = Eigen::Vector3d::Zero();
};

struct SensorModel {
  std::string name;  // unique in the car model, e.g. "front_camera"
  SensorKind kind = SensorKind::kCamera;
  // The device model: "pinhole" / "fisheye" for cameras (the projection model),
  // "vlp16" / "pandar64" / "pandarxt32" for LiDARs, "ars408" / "esr" for radars.
  std::string model;
  Rigid3d T_car_sensor_nominal;
  MountingTolerance tolerance;
  // Cameras only.
  std::optional<CameraIntrinsics> intrinsics;
  // LiDARs only: a per-unit angle correction file (Pandar64 / PandarXT-32 CSV), resolved
  // relative to the car model file; empty for the model's default table.
  std::string angles_file;
  // Radars only: the ARS408 sensor id (0..7), which offsets its CAN ids by 0x10 per id.
  int radar_sensor_id = 0;
  // Board ids (cameras, LiDARs) or reflector ids (radars) of the station layout that this
  // sensor must see.
  std::vector<std::string> targets;
};

// R_base of each sensor kind (docs/conventions.md): the orientation at yaw = pitch = roll = 0.
// Cameras: CameraBaseRotation(). LiDARs: LidarBaseRotation() (the vendor frame has y at
// azimuth 0, which faces forward). Radars: identity (x along the boresight, y left, z up).
Eigen::Matrix3d SensorBaseRotation(SensorKind kind);

struct CarModel {
  std::string id;  // e.g. "reference"
  std::string description;
  std::vector<SensorModel> sensors;

  const SensorModel* FindSensor(const std::string& name) const;
};

// Reads a car model file. Errors name the file and the field. Sensor names must be unique;
// the model must suit the kind; cameras need valid intrinsics.
absl::StatusOr<CarModel> ReadCarModel(const std::string& path);
absl::StatusOr<CarModel> ParseCarModel(const std::string& text, const std::string& source);
nlohmann::json CarModelToJson(const CarModel& car);

// The beam table of a LiDAR of the car model: its unit's angle file when it has one, else
// the model's built-in table. Errors: InvalidArgument for an unknown model (callers add the
// sensor's name), the angle file's errors (naming it). O(channels).
absl::StatusOr<LidarBeamTable> LidarBeamTableOf(const SensorModel& sensor);

// Checks that every target a sensor names exists in the layout (boards for cameras and
// LiDARs, reflectors for radars). Errors name the sensor and the target.
absl::Status CheckTargetsExist(const CarModel& car, const StationLayout& layout);

}  // namespace linecal
