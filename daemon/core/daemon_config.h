#pragma once
// linecald's configuration file (docs/daemon.md): JSON, every key checked, errors naming the
// file and the key ("linecald.json: source.type: must be 'simulator', 'replay' or 'live', got 'usb'").
// Relative paths in the file are relative to the file's directory.

#include <string>

#include "absl/status/statusor.h"
#include "daemon/core/station_core.h"

namespace linecal {

struct DaemonConfig {
  std::string listen = "127.0.0.1:50051";  // HOST:PORT
  std::string log_level = "info";          // "debug", "info", "warning", "error"
  std::string auth_token;                  // empty: no authentication
  StationCoreConfig core;
};

// The configuration without a file: the bundled demo station and car of `deploy_dir`, the
// simulator source, data and database under `data_dir`.
DaemonConfig DefaultDaemonConfig(const std::string& deploy_dir, const std::string& data_dir);

// Reads a configuration file. Keys: listen, log_level, auth_token, station_id, station,
// car_models (array), data_root, db, source {type: simulator|replay, capture} or
// {type: live, sensors: {NAME: {type: aravis|v4l2|udp|socketcan|candump, ...}}},
// vin_check_digit, frames_per_sensor, busy_timeout_ms, deadlines_ms {acquire, calibrate};
// unknown keys are errors. Whether every sensor has a source of its kind is checked by
// StationCore::Create, which knows the car models.
absl::StatusOr<DaemonConfig> ReadDaemonConfig(const std::string& path);

}  // namespace linecal
