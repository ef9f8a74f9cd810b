#pragma once
// The station's health as the console's JSON (GET /api/trends, docs/console.md): the field
// names of station/health/station_health.h and of the gRPC TargetAlarm.

#include <nlohmann/json.hpp>
#include <string>

#include "station/health/station_health.h"

namespace linecal {

// {car_model, targets, sensors [{sensor, baseline_residual, recent_residual, shift_sigmas}],
// since_cycle_id, last_cycle_id, statistic_sigmas, alarm_sigmas}. Pure.
nlohmann::json TargetAlarmJson(const TargetAlarm& alarm);

// {trends: [{car_model, sensor, kind, targets, series: [{name, cycle_ids, values, ewma, mean,
// sigma, lower, upper, tolerance}]}], alarms, counts: [{car_model, target, sensors, cycle_ids,
// detected, frames_found, frames}]}, the trends of `sensor` only and the counts of its targets when
// `sensor` is not empty (a page of 10,000 cycles of every sensor would be tens of MB). Pure;
// O(size).
nlohmann::json TrendsJson(const StationHealth& health, const std::string& sensor);

}  // namespace linecal
