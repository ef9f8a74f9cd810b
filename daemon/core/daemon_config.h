#pragma once
// linecald's configuration file (docs/daemon.md): JSON, every key checked, errors naming the
// file and the key ("linecald.json: source.type: must be 'simulator' or 'replay', got 'usb'").
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
// car_models (array), data_root, db, source {type: simulator|replay, capture}, vin_check_digit,
// frames_per_sensor, busy_timeout_ms; unknown keys are errors.
absl::StatusOr<DaemonConfig> ReadDaemonConfig(const std::string& path);

}  // namespace linecal
