#include "daemon/web/console_json.h"

#include <numbers>

#include "daemon/web/trends_json.h"
#include "detectors/core/pose.h"

namespace linecal {
namespace {

constexpr double kDegPerRad = 180.0 / std::numbers::pi;

nlohmann::json MountingJson(const MountingValues& m) {
  return {{"yaw_deg", m.yaw_deg},   {"pitch_deg", m.pitch_deg},
          {"roll_deg", m.roll_deg}, {"x_m", m.x_m},
          {"y_m", m.y_m},           {"z_m", m.z_m}};
}

nlohmann::json SensorJson(const StoredSensorResult& s) {
  nlohmann::json j = {{"name", s.sensor},
                      {"kind", SensorKindName(s.kind)},
                      {"verdict", VerdictName(s.verdict)},
                      {"reason", s.reason},
                      {"message", s.message},
                      {"t_car_sensor", s.T_car_sensor},
                      {"mounting", MountingJson(s.measured)},
                      {"deviation", MountingJson(s.deviation)},
                      {"uncertainty", MountingJson(s.sigma)},
                      {"residual_rms", s.residual_rms},
                      {"features_used", s.features_used}};
  // As in gRPC's SensorResult: the vanishing point only when both coordinates are known.
  if (s.vanishing_point_u_px && s.vanishing_point_v_px) {
    j["vanishing_point_u_px"] = *s.vanishing_point_u_px;
    j["vanishing_point_v_px"] = *s.vanishing_point_v_px;
  }
  if (!s.ground_homography.empty()) j["ground_homography"] = s.ground_homography;
  return j;
}

}  // namespace

nlohmann::json CycleJson(const StoredCycle& c, bool with_sensors) {
  nlohmann::json j = {{"cycle_id", std::to_string(c.id)},  {"vin", c.vin},
                      {"car_model_id", c.car_model_id},    {"state", CycleStateName(c.state)},
                      {"verdict", VerdictName(c.verdict)}, {"reason", c.reason},
                      {"started_ns", c.started_ns},        {"ended_ns", c.ended_ns},
                      {"capture_path", c.capture_path}};
  if (!with_sensors) return j;
  nlohmann::json sensors = nlohmann::json::array();
  for (const StoredSensorResult& s : c.sensors) sensors.push_back(SensorJson(s));
  j["sensors"] = std::move(sensors);
  return j;
}

nlohmann::json EventJson(const StoredEvent& e) {
  return {
      {"cycle_id", std::to_string(e.cycle_id)}, {"sequence", e.sequence}, {"time_ns", e.time_ns},
      {"type", EventTypeName(e.type)},          {"sensor", e.sensor},     {"detail", e.detail},
      {"verdict", VerdictName(e.verdict)}};
}

nlohmann::json StatusJson(const StationStatusInfo& s, const std::string& version) {
  nlohmann::json alarms = nlohmann::json::array();
  for (const TargetAlarm& a : s.target_alarms) alarms.push_back(TargetAlarmJson(a));
  nlohmann::json sensors = nlohmann::json::array();
  for (const auto& [name, kind] : s.sensors) {
    sensors.push_back(
        {{"name", name}, {"kind", SensorKindName(kind)}, {"source", s.SourceOf(name)}});
  }
  return {{"version", version},
          {"station_id", s.station_id},
          {"car_models", s.car_models},
          {"source", s.source},
          {"running_cycle_id", s.running_cycle ? std::to_string(*s.running_cycle) : ""},
          {"disk_free_bytes", s.disk_free_bytes},
          {"sensors", std::move(sensors)},
          {"target_alarms", std::move(alarms)}};
}

nlohmann::json CarModelJson(const CarModel& car) {
  nlohmann::json sensors = nlohmann::json::array();
  for (const SensorModel& s : car.sensors) {
    const Rigid3d& nominal = s.T_car_sensor_nominal;
    const YawPitchRoll a = MountingAngles(nominal.RotationMatrix(), SensorBaseRotation(s.kind));
    const MountingTolerance& t = s.tolerance;
    sensors.push_back(
        {{"name", s.name},
         {"kind", SensorKindName(s.kind)},
         {"model", s.model},
         {"targets", s.targets},
         {"nominal", MountingJson({a.yaw * kDegPerRad, a.pitch * kDegPerRad, a.roll * kDegPerRad,
                                   nominal.translation().x(), nominal.translation().y(),
                                   nominal.translation().z()})},
         {"tolerance",
          MountingJson({t.yaw_rad * kDegPerRad, t.pitch_rad * kDegPerRad, t.roll_rad * kDegPerRad,
                        t.xyz_m.x(), t.xyz_m.y(), t.xyz_m.z()})}});
  }
  return {{"id", car.id}, {"description", car.description}, {"sensors", std::move(sensors)}};
}

}  // namespace linecal
