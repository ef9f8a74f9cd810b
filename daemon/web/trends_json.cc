#include "daemon/web/trends_json.h"

#include <algorithm>

namespace linecal {

nlohmann::json TargetAlarmJson(const TargetAlarm& a) {
  nlohmann::json sensors = nlohmann::json::array();
  for (const ShiftedSensor& s : a.sensors) {
    sensors.push_back({{"sensor", s.sensor},
                       {"baseline_residual", s.baseline_residual},
                       {"recent_residual", s.recent_residual},
                       {"shift_sigmas", s.shift_sigmas}});
  }
  return {{"car_model", a.car_model},
          {"targets", a.targets},
          {"sensors", std::move(sensors)},
          {"since_cycle_id", std::to_string(a.since_cycle)},
          {"last_cycle_id", std::to_string(a.last_cycle)},
          {"statistic_sigmas", a.statistic_sigmas},
          {"alarm_sigmas", a.alarm_sigmas}};
}

nlohmann::json TrendsJson(const StationHealth& health, const std::string& sensor) {
  nlohmann::json trends = nlohmann::json::array();
  std::vector<std::string> targets;
  for (const SensorTrend& t : health.trends) {
    if (!sensor.empty() && t.sensor != sensor) continue;
    targets.insert(targets.end(), t.targets.begin(), t.targets.end());
    nlohmann::json series = nlohmann::json::array();
    for (const HealthSeries& s : t.series) {
      series.push_back({{"name", s.name},
                        {"cycle_ids", s.cycle_ids},
                        {"values", s.values},
                        {"ewma", s.ewma},
                        {"mean", s.mean},
                        {"sigma", s.sigma},
                        {"lower", s.lower},
                        {"upper", s.upper},
                        {"tolerance", s.tolerance}});
    }
    trends.push_back({{"car_model", t.car_model},
                      {"sensor", t.sensor},
                      {"kind", t.kind},
                      {"targets", t.targets},
                      {"series", std::move(series)}});
  }
  nlohmann::json alarms = nlohmann::json::array();
  for (const TargetAlarm& a : health.alarms) alarms.push_back(TargetAlarmJson(a));
  nlohmann::json counts = nlohmann::json::array();
  for (const TargetCounts& c : health.counts) {
    if (!sensor.empty() && std::find(targets.begin(), targets.end(), c.target) == targets.end())
      continue;
    counts.push_back({{"car_model", c.car_model},
                      {"target", c.target},
                      {"sensors", c.sensors},
                      {"cycle_ids", c.cycle_ids},
                      {"detected", c.detected},
                      {"frames_found", c.frames_found},
                      {"frames", c.frames}});
  }
  return {
      {"trends", std::move(trends)}, {"alarms", std::move(alarms)}, {"counts", std::move(counts)}};
}

}  // namespace linecal
