#pragma once
// The console's JSON (docs/console.md, "API"): the station core's records as the pages read
// them. Field names are those of the gRPC messages (proto/linecal/v1/station.proto: Cycle,
// SensorResult, MountingAngles, CycleEvent, StationStatus), so that one vocabulary serves both
// APIs; enums are the store's words ("pass", "done", "sensor_verdict"), cycle ids decimal
// strings as in gRPC. Pure functions; cost linear in the record.

#include <nlohmann/json.hpp>
#include <string>

#include "daemon/core/station_core.h"
#include "daemon/store/store.h"
#include "station/model/car_model.h"

namespace linecal {

// A cycle: cycle_id, vin, car_model_id, state, verdict, reason, started_ns, ended_ns,
// capture_path, and with `with_sensors` its sensors (name, kind, verdict, reason, message,
// t_car_sensor (16 values, row-major; [] when not solved), mounting, deviation, uncertainty
// ({yaw_deg, pitch_deg, roll_deg, x_m, y_m, z_m} each), residual_rms, features_used, and for
// cameras vanishing_point_u_px/_v_px and ground_homography).
nlohmann::json CycleJson(const StoredCycle& cycle, bool with_sensors);

// One event of a cycle: cycle_id, sequence, time_ns, type, sensor, detail, verdict.
nlohmann::json EventJson(const StoredEvent& event);

// The station: version, station_id, car_models, source, running_cycle_id ("" when idle),
// disk_free_bytes, sensors [{name, kind, source}].
nlohmann::json StatusJson(const StationStatusInfo& status, const std::string& version);

// A car model as the cycle page compares against it: id, description, sensors [{name, kind,
// model, targets, nominal {yaw_deg, pitch_deg, roll_deg, x_m, y_m, z_m} (the angles of
// docs/conventions.md, as the solvers measure them), tolerance (the same keys: the largest
// deviation allowed either way)}].
nlohmann::json CarModelJson(const CarModel& car);

}  // namespace linecal
