#pragma once
// linecald's configuration file (docs/daemon.md): JSON, every key checked, errors naming the
// file and the key ("linecald.json: source.type: must be 'simulator', 'replay' or 'live', got
// 'usb'"). Relative paths in the file are relative to the file's directory.

#include <optional>
#include <string>

#include "absl/status/statusor.h"
#include "daemon/core/station_core.h"
#include "station/io/input_budget.h"

namespace linecal {

// The `tls` key (docs/daemon.md, "Authentication"): the server's certificate and key and the CA
// that signs the clients' certificates. The files are read with the configuration, so that a
// missing one stops the daemon at start-up naming the key and the file; whether the PEM text
// parses and the key matches the certificate is checked where the gRPC credentials are made
// (daemon/service/tls_credentials.h).
struct TlsConfig {
  // Resolved paths, for messages; client_ca_path is empty when the key is absent.
  std::string cert_path;
  std::string key_path;
  std::string client_ca_path;
  // The files' contents (PEM).
  std::string cert_pem;
  std::string key_pem;
  std::string client_ca_pem;
  // True: a client without a certificate signed by client_ca fails the handshake. False with a
  // client_ca: a certificate is asked for and verified when the client sends one.
  bool require_client_cert = true;
};

// The `web` key (docs/daemon.md, "Console"): the station console's HTTP server (daemon/web).
struct WebConfig {
  std::string listen;            // HOST:PORT, checked by CheckListenAddress
  std::optional<TlsConfig> tls;  // absent: plain HTTP
  // The pages' folder; empty: found from the binary's place (daemon/web/web_server.h).
  std::string static_dir;
  // A login with it is an operator session (start and cancel cycles from the live page);
  // empty: nobody may (docs/console.md, "Login and roles"). Never equal to auth_token.
  std::string operator_token;
};

struct DaemonConfig {
  std::string listen = "127.0.0.1:50051";  // HOST:PORT
  std::string log_level = "info";          // "debug", "info", "warning", "error"
  std::string auth_token;                  // empty: no authentication
  std::optional<TlsConfig> tls;            // absent: an insecure port
  std::optional<WebConfig> web;            // absent: no console (no HTTP port)
  // What one input file of a capture may claim (station/io/input_budget.h); the `input_budget`
  // key, each field optional with InputBudget's default.
  InputBudget input_budget;
  StationCoreConfig core;
};

// The configuration without a file: the bundled demo station and car of `deploy_dir`, the
// simulator source, data and database under `data_dir`.
DaemonConfig DefaultDaemonConfig(const std::string& deploy_dir, const std::string& data_dir);

// `address` as the servers take it: HOST:PORT ("[::1]:50051" too) with a decimal port in
// 0..65535, else InvalidArgument naming `key` ("web.listen: '...': must be HOST:PORT ...").
// Pure.
absl::Status CheckListenAddress(const std::string& address, const std::string& key = "listen");

// Reads a configuration file. Keys: listen, log_level, auth_token, station_id, station,
// car_models (array), data_root, db, source {type: simulator|replay, capture} or
// {type: live, sensors: {NAME: {type: aravis|v4l2|udp|socketcan|candump, ...}}},
// vin_check_digit, frames_per_sensor, busy_timeout_ms, deadlines_ms {acquire, calibrate},
// tls {cert, key, client_ca, require_client_cert: cert and key required, client_ca too unless
// require_client_cert is false}, input_budget {max_file_bytes, max_image_pixels,
// max_scan_points, max_can_lines, max_manifest_frames: integers >= 1}, plant {dsn,
// station_id (default: the top-level one), batch, password_file, max_backlog_age_s,
// max_retry_interval_s, tls {mode, ca, cert, key}} (daemon/plant/forwarder.h's PlantConfig: the
// DSN must parse and hold no password, the files must exist), web {listen (required, checked by
// CheckListenAddress), tls (as the top-level tls), static_dir (relative to the file)};
// unknown keys are errors.
// A replay capture (source.capture) must resolve inside data_root, symbolic links followed
// (checked when data_root exists: "source.capture: 'cap': resolves outside data_root").
// Whether every sensor has a source of its kind is checked by StationCore::Create, which knows
// the car models. Cost: reads the file and the tls PEM files.
absl::StatusOr<DaemonConfig> ReadDaemonConfig(const std::string& path);

}  // namespace linecal
