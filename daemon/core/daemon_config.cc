#include "daemon/core/daemon_config.h"

#include <filesystem>

#include "absl/strings/str_cat.h"
#include "station/io/json_reader.h"

namespace linecal {
namespace {

namespace fs = std::filesystem;

std::string Resolve(const fs::path& base, const std::string& p) {
  return fs::path(p).is_absolute() ? p : (base / p).lexically_normal().string();
}

absl::StatusOr<TlsConfig> ReadTls(const JsonField& tls, const fs::path& base) {
  if (absl::Status s = tls.AllowOnlyKeys({"cert", "key", "client_ca", "require_client_cert"}); !s.ok()) return s;
  TlsConfig c;
  // One PEM file: a path key, resolved against the configuration's directory, and its text.
  auto read = [&](const char* key, bool required, std::string* path, std::string* pem) -> absl::Status {
    absl::StatusOr<std::string> value = required ? tls.String(key) : tls.StringOr(key, "");
    if (!value.ok()) return value.status();
    if (value->empty()) return absl::OkStatus();
    *path = Resolve(base, *value);
    absl::StatusOr<std::string> text = ReadTextFile(*path);
    if (!text.ok()) return tls.Error(key, std::string(text.status().message()));
    *pem = *std::move(text);
    return absl::OkStatus();
  };
  if (absl::Status s = read("cert", true, &c.cert_path, &c.cert_pem); !s.ok()) return s;
  if (absl::Status s = read("key", true, &c.key_path, &c.key_pem); !s.ok()) return s;
  if (absl::Status s = read("client_ca", false, &c.client_ca_path, &c.client_ca_pem); !s.ok()) return s;
  absl::StatusOr<bool> require = tls.BoolOr("require_client_cert", true);
  if (!require.ok()) return require.status();
  c.require_client_cert = *require;
  if (c.require_client_cert && c.client_ca_path.empty()) {
    return tls.Error("client_ca", "required when require_client_cert is true (the CA of the clients' certificates)");
  }
  return c;
}

}  // namespace

DaemonConfig DefaultDaemonConfig(const std::string& deploy_dir, const std::string& data_dir) {
  DaemonConfig c;
  c.core.station_id = "demo";
  c.core.station_path = deploy_dir + "/stations/reference.json";
  c.core.car_model_paths = {deploy_dir + "/cars/reference.json"};
  c.core.data_root = data_dir;
  c.core.db_path = data_dir + "/linecal.db";
  c.core.source = CycleSource::kSimulator;
  return c;
}

absl::StatusOr<DaemonConfig> ReadDaemonConfig(const std::string& path) {
  absl::StatusOr<JsonDocument> doc = JsonDocument::FromFile(path);
  if (!doc.ok()) return doc.status();
  absl::StatusOr<JsonField> root = doc->Root();
  if (!root.ok()) return root.status();
  if (absl::Status s = root->AllowOnlyKeys({"listen", "log_level", "auth_token", "station_id", "station", "car_models",
                                            "data_root", "db", "source", "vin_check_digit", "frames_per_sensor",
                                            "busy_timeout_ms", "tls"});
      !s.ok()) {
    return s;
  }
  const fs::path base = fs::path(path).parent_path();
  DaemonConfig c;
  absl::StatusOr<std::string> listen = root->StringOr("listen", c.listen);
  if (!listen.ok()) return listen.status();
  c.listen = *listen;
  absl::StatusOr<std::string> level = root->StringOr("log_level", c.log_level);
  if (!level.ok()) return level.status();
  if (*level != "debug" && *level != "info" && *level != "warning" && *level != "error") {
    return root->Error("log_level", absl::StrCat("must be debug, info, warning or error, got '", *level, "'"));
  }
  c.log_level = *level;
  absl::StatusOr<std::string> token = root->StringOr("auth_token", "");
  if (!token.ok()) return token.status();
  c.auth_token = *token;
  absl::StatusOr<std::string> id = root->StringOr("station_id", "station");
  if (!id.ok()) return id.status();
  c.core.station_id = *id;
  absl::StatusOr<std::string> station = root->String("station");
  if (!station.ok()) return station.status();
  c.core.station_path = Resolve(base, *station);
  absl::StatusOr<std::vector<JsonField>> cars = root->Array("car_models");
  if (!cars.ok()) return cars.status();
  for (const JsonField& f : *cars) {
    absl::StatusOr<std::string> car = f.AsString();
    if (!car.ok()) return car.status();
    c.core.car_model_paths.push_back(Resolve(base, *car));
  }
  absl::StatusOr<std::string> data_root = root->String("data_root");
  if (!data_root.ok()) return data_root.status();
  c.core.data_root = Resolve(base, *data_root);
  absl::StatusOr<std::string> db = root->StringOr("db", "linecal.db");
  if (!db.ok()) return db.status();
  c.core.db_path = fs::path(*db).is_absolute() ? *db : (fs::path(c.core.data_root) / *db).string();
  if (root->Has("source")) {
    absl::StatusOr<JsonField> source = root->Object("source");
    if (!source.ok()) return source.status();
    if (absl::Status s = source->AllowOnlyKeys({"type", "capture"}); !s.ok()) return s;
    absl::StatusOr<std::string> type = source->String("type");
    if (!type.ok()) return type.status();
    if (*type == "simulator") {
      c.core.source = CycleSource::kSimulator;
    } else if (*type == "replay") {
      c.core.source = CycleSource::kReplay;
      absl::StatusOr<std::string> capture = source->String("capture");
      if (!capture.ok()) return capture.status();
      c.core.replay_capture = *capture;
    } else {
      return source->Error("type", absl::StrCat("must be 'simulator' or 'replay', got '", *type, "'"));
    }
  }
  absl::StatusOr<bool> check = root->BoolOr("vin_check_digit", true);
  if (!check.ok()) return check.status();
  c.core.vin_check_digit = *check;
  absl::StatusOr<std::int64_t> frames = root->IntegerOr("frames_per_sensor", 1);
  if (!frames.ok()) return frames.status();
  if (*frames < 1 || *frames > 100) return root->Error("frames_per_sensor", "must be in [1, 100]");
  c.core.default_frames_per_sensor = static_cast<int>(*frames);
  absl::StatusOr<std::int64_t> busy = root->IntegerOr("busy_timeout_ms", 5000);
  if (!busy.ok()) return busy.status();
  if (*busy < 0 || *busy > 600000) return root->Error("busy_timeout_ms", "must be in [0, 600000]");
  c.core.busy_timeout = std::chrono::milliseconds(*busy);
  if (root->Has("tls")) {
    absl::StatusOr<JsonField> tls_field = root->Object("tls");
    if (!tls_field.ok()) return tls_field.status();
    absl::StatusOr<TlsConfig> tls = ReadTls(*tls_field, base);
    if (!tls.ok()) return tls.status();
    c.tls = *std::move(tls);
  }
  return c;
}

}  // namespace linecal
