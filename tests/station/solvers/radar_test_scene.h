#pragma once
// A small station and radars for the radar calibration tests: three corner reflectors 8 m
// ahead (centre and ±2.5 m), one behind the car, and a radar in the front bumper.

#include <numbers>
#include <string>
#include <vector>

#include "detectors/core/pose.h"
#include "station/model/car_model.h"
#include "station/model/station_layout.h"
#include "station/sensors/radar/radar_decoder.h"
#include "station/sim/radar_sim.h"

namespace linecal::radar_test {

inline constexpr double kDeg = std::numbers::pi / 180.0;

inline StationLayout TestLayout() {
  StationLayout layout;
  layout.name = "radar_test";
  layout.reflectors = {{"centre", Eigen::Vector3d(12.0, 0.0, 0.45), 20.0},
                       {"left", Eigen::Vector3d(12.0, 2.5, 0.45), 20.0},
                       {"right", Eigen::Vector3d(12.0, -2.5, 0.45), 20.0},
                       {"behind", Eigen::Vector3d(-6.0, 0.0, 0.45), 20.0}};
  return layout;
}

// A radar at the bumper (4 m ahead of the car origin, 0.45 m up) looking ahead, with the
// reference car's tolerances (1° per angle, 5 cm per axis).
inline SensorModel TestRadar(const std::string& model, double yaw_rad = 0.0) {
  SensorModel s;
  s.name = "front_radar";
  s.kind = SensorKind::kRadar;
  s.model = model;
  s.T_car_sensor_nominal =
      Rigid3d(Eigen::Matrix3d(Eigen::AngleAxisd(yaw_rad, Eigen::Vector3d::UnitZ())),
              Eigen::Vector3d(4.0, 0.0, 0.45));
  s.tolerance.yaw_rad = 1.0 * kDeg;
  s.tolerance.pitch_rad = 1.0 * kDeg;
  s.tolerance.roll_rad = 1.0 * kDeg;
  s.tolerance.xyz_m = Eigen::Vector3d::Constant(0.05);
  s.targets = {"centre", "left", "right"};
  return s;
}

// The sensor's true pose: nominal with its mounting angles moved by `error` and its position
// by `offset` (car frame, metres).
inline Rigid3d TrueMounting(const SensorModel& s, const YawPitchRoll& error,
                            const Eigen::Vector3d& offset = Eigen::Vector3d::Zero()) {
  const YawPitchRoll nominal =
      MountingAngles(s.T_car_sensor_nominal.RotationMatrix(), Eigen::Matrix3d::Identity());
  return Rigid3d(RotationFromYawPitchRoll({nominal.yaw + error.yaw, nominal.pitch + error.pitch,
                                           nominal.roll + error.roll}),
                 s.T_car_sensor_nominal.translation() + offset);
}

// A corner radar's station: two reflectors about 5.5 m away as on the reference station and
// one 2.2 m away, 10° off the boresight of a radar at (3.6, 0.85) yawed 40° (TestCornerRadar):
// reflectors at clearly different ranges, so that the radar's offset across the line of sight
// can be told from its yaw.
inline StationLayout CornerLayout() {
  StationLayout layout;
  layout.name = "radar_corner_test";
  layout.reflectors = {{"near", Eigen::Vector3d(6.0, 5.5, 0.5), 15.0},
                       {"far", Eigen::Vector3d(7.5, 5.0, 0.5), 15.0},
                       {"close", Eigen::Vector3d(5.014, 2.535, 0.5), 15.0}};
  return layout;
}

// The reference car's left ESR corner radar, with the tolerances of TestRadar.
inline SensorModel TestCornerRadar() {
  SensorModel s = TestRadar("esr", 40 * kDeg);
  s.name = "corner_radar_left";
  s.T_car_sensor_nominal =
      Rigid3d(s.T_car_sensor_nominal.RotationMatrix(), Eigen::Vector3d(3.6, 0.85, 0.5));
  s.targets = {"near", "far", "close"};
  return s;
}

// Simulated CAN traffic of the radar at T_station_car * T_car_radar, decoded back to cycles.
inline std::vector<RadarCycle> SimulatedCycles(const SensorModel& s, const StationLayout& layout,
                                               const Rigid3d& T_station_car,
                                               const Rigid3d& T_car_radar,
                                               const RadarSimOptions& options, std::uint64_t seed) {
  const absl::StatusOr<std::vector<CanFrame>> frames =
      SimulateRadar(s.model, s.radar_sensor_id, layout, T_station_car * T_car_radar, CanTime{},
                    "can0", options, seed);
  if (!frames.ok()) return {};
  return DecodeRadarFrames(*frames, *ParseRadarModel(s.model), RadarConventions{}).cycles;
}

}  // namespace linecal::radar_test
