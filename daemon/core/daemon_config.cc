#include "daemon/core/daemon_config.h"

#include <algorithm>
#include <filesystem>

#include "absl/strings/ascii.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "station/capture/capture.h"
#include "station/io/json_reader.h"

namespace linecal {
namespace {

namespace fs = std::filesystem;

std::string Resolve(const fs::path& base, const std::string& p) {
  return fs::path(p).is_absolute() ? p : (base / p).lexically_normal().string();
}

absl::StatusOr<TlsConfig> ReadTls(const JsonField& tls, const fs::path& base) {
  if (absl::Status s = tls.AllowOnlyKeys({"cert", "key", "client_ca", "require_client_cert"});
      !s.ok())
    return s;
  TlsConfig c;
  // One PEM file: a path key, resolved against the configuration's directory, and its text.
  auto read = [&](const char* key, bool required, std::string* path,
                  std::string* pem) -> absl::Status {
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
  if (absl::Status s = read("client_ca", false, &c.client_ca_path, &c.client_ca_pem); !s.ok())
    return s;
  absl::StatusOr<bool> require = tls.BoolOr("require_client_cert", true);
  if (!require.ok()) return require.status();
  c.require_client_cert = *require;
  if (c.require_client_cert && c.client_ca_path.empty()) {
    return tls.Error(
        "client_ca",
        "required when require_client_cert is true (the CA of the clients' certificates)");
  }
  return c;
}

// A duration key: integer milliseconds in [1, 600000]; ten minutes is beyond any step of a
// cycle, so a larger number is a unit mistake.
absl::StatusOr<std::chrono::milliseconds> Milliseconds(const JsonField& f, const std::string& key,
                                                       std::chrono::milliseconds fallback) {
  absl::StatusOr<std::int64_t> ms = f.IntegerOr(key, fallback.count());
  if (!ms.ok()) return ms.status();
  if (*ms <= 0 || *ms > 600000)
    return f.Error(key, absl::StrCat("must be in [1, 600000], got ", *ms));
  return std::chrono::milliseconds(*ms);
}

// One sensor's entry of source.sensors (docs/daemon.md, "Live sources"); only parsing and
// the ranges of the keys here, the sources check the rest when they are built.
absl::StatusOr<SourceConfig> ParseSensorSource(const JsonField& f, const fs::path& base) {
  absl::StatusOr<std::string> type = f.String("type");
  if (!type.ok()) return type.status();
  SourceConfig c;
  if (*type == "aravis" || *type == "v4l2") {
    const bool aravis = *type == "aravis";
    c.type = aravis ? SourceType::kAravis : SourceType::kV4l2;
    absl::Status keys = aravis
                            ? f.AllowOnlyKeys({"type", "device_id", "pixel_format", "exposure_us",
                                               "frame_timeout_ms", "frame_retries"})
                            : f.AllowOnlyKeys({"type", "device", "pixel_format", "width", "height",
                                               "frame_timeout_ms", "frame_retries"});
    if (!keys.ok()) return keys;
    absl::StatusOr<std::chrono::milliseconds> timeout =
        Milliseconds(f, "frame_timeout_ms", c.aravis.frame_timeout);
    if (!timeout.ok()) return timeout.status();
    absl::StatusOr<std::int64_t> retries = f.IntegerOr("frame_retries", c.aravis.frame_retries);
    if (!retries.ok()) return retries.status();
    // More than 100 retries of one frame is a camera that does not work.
    if (*retries < 0 || *retries > 100) return f.Error("frame_retries", "must be in [0, 100]");
    if (aravis) {
      absl::StatusOr<std::string> id = f.String("device_id");
      if (!id.ok()) return id.status();
      absl::StatusOr<std::string> format = f.StringOr("pixel_format", c.aravis.pixel_format);
      if (!format.ok()) return format.status();
      absl::StatusOr<double> exposure = f.NumberOr("exposure_us", c.aravis.exposure_us);
      if (!exposure.ok()) return exposure.status();
      if (*exposure < 0) return f.Error("exposure_us", "must be >= 0 (0: the camera's own)");
      c.aravis = {*id, *format, *exposure, *timeout, static_cast<int>(*retries)};
    } else {
      absl::StatusOr<std::string> device = f.StringOr("device", c.v4l2.device);
      if (!device.ok()) return device.status();
      absl::StatusOr<std::string> format = f.StringOr("pixel_format", c.v4l2.pixel_format);
      if (!format.ok()) return format.status();
      absl::StatusOr<std::int64_t> width = f.IntegerOr("width", 0);
      if (!width.ok()) return width.status();
      absl::StatusOr<std::int64_t> height = f.IntegerOr("height", 0);
      if (!height.ok()) return height.status();
      // 16384: beyond any V4L2 camera's sensor; 0 keeps the device's format.
      if (*width < 0 || *width > 16384) return f.Error("width", "must be in [0, 16384]");
      if (*height < 0 || *height > 16384) return f.Error("height", "must be in [0, 16384]");
      c.v4l2 = {*device,
                *format,
                static_cast<int>(*width),
                static_cast<int>(*height),
                *timeout,
                static_cast<int>(*retries)};
    }
    return c;
  }
  if (*type == "udp") {
    c.type = SourceType::kUdp;
    if (absl::Status s =
            f.AllowOnlyKeys({"type", "bind", "port", "multicast_group", "receive_buffer_bytes"});
        !s.ok()) {
      return s;
    }
    absl::StatusOr<std::string> bind = f.StringOr("bind", c.udp.bind_address);
    if (!bind.ok()) return bind.status();
    absl::StatusOr<std::int64_t> port = f.IntegerOr("port", c.udp.port);
    if (!port.ok()) return port.status();
    if (*port < 1 || *port > 65535)
      return f.Error("port", absl::StrCat("must be in [1, 65535], got ", *port));
    absl::StatusOr<std::string> group = f.StringOr("multicast_group", "");
    if (!group.ok()) return group.status();
    absl::StatusOr<std::int64_t> buffer =
        f.IntegerOr("receive_buffer_bytes", c.udp.receive_buffer_bytes);
    if (!buffer.ok()) return buffer.status();
    // 1 GiB: more than any kernel grants; a larger number is a unit mistake.
    if (*buffer < 1 || *buffer > (1 << 30))
      return f.Error("receive_buffer_bytes", "must be in [1, 2^30]");
    c.udp = {*bind, static_cast<std::uint16_t>(*port), *group, static_cast<int>(*buffer)};
    if (absl::Status s = c.udp.Validate(); !s.ok()) return f.Error(std::string(s.message()));
    return c;
  }
  if (*type == "socketcan" || *type == "candump") {
    const bool log = *type == "candump";
    c.type = log ? SourceType::kCandump : SourceType::kSocketCan;
    c.can.input =
        log ? CanRadarSourceConfig::Input::kCandumpLog : CanRadarSourceConfig::Input::kSocketCan;
    absl::Status keys = log ? f.AllowOnlyKeys({"type", "log", "interface", "record_ms"})
                            : f.AllowOnlyKeys({"type", "interface", "record_ms"});
    if (!keys.ok()) return keys;
    absl::StatusOr<std::string> interface =
        log ? f.StringOr("interface", "") : f.String("interface");
    if (!interface.ok()) return interface.status();
    c.can.interface = *interface;
    if (log) {
      absl::StatusOr<std::string> path = f.String("log");
      if (!path.ok()) return path.status();
      c.can.log_path = Resolve(base, *path);
    }
    absl::StatusOr<std::chrono::milliseconds> record = Milliseconds(f, "record_ms", c.can.record);
    if (!record.ok()) return record.status();
    c.can.record = *record;
    if (absl::Status s = c.can.Validate(); !s.ok()) return f.Error(std::string(s.message()));
    return c;
  }
  return f.Error(
      "type", absl::StrCat("must be aravis, v4l2, udp, socketcan or candump, got '", *type, "'"));
}

// The `input_budget` object: each key optional, an integer >= 1 (InputBudget::Validate).
absl::StatusOr<InputBudget> ReadInputBudget(const JsonField& f) {
  InputBudget b;
  const std::pair<const char*, std::int64_t*> keys[] = {
      {"max_file_bytes", &b.max_file_bytes},
      {"max_image_pixels", &b.max_image_pixels},
      {"max_scan_points", &b.max_scan_points},
      {"max_can_lines", &b.max_can_lines},
      {"max_manifest_frames", &b.max_manifest_frames}};
  if (absl::Status s = f.AllowOnlyKeys({"max_file_bytes", "max_image_pixels", "max_scan_points",
                                        "max_can_lines", "max_manifest_frames"});
      !s.ok()) {
    return s;
  }
  for (const auto& [key, slot] : keys) {
    absl::StatusOr<std::int64_t> v = f.IntegerOr(key, *slot);
    if (!v.ok()) return v.status();
    if (*v < 1) return f.Error(key, absl::StrCat("must be >= 1, got ", *v));
    *slot = *v;
  }
  return b;
}

// A replay capture may not leave data_root through a symbolic link (a capture folder that is
// a link elsewhere). Checked only when data_root exists: otherwise there is no capture yet,
// and StationCore::Create reports that.
absl::Status CheckReplayInside(const JsonField& source, const std::string& data_root,
                               const std::string& capture) {
  std::error_code ec;
  if (!fs::is_directory(data_root, ec)) return absl::OkStatus();
  const absl::StatusOr<fs::path> r =
      ResolveInside(data_root, capture, absl::StrCat("'", capture, "'"), "data_root");
  if (!r.ok()) return source.Error("capture", std::string(r.status().message()));
  return absl::OkStatus();
}

// The `plant` object (docs/daemon.md, "Plant database"): the DSN checked and its password
// refused by PlantConnectionString, the password file read now so that a missing one stops
// the daemon at start-up naming the key.
absl::StatusOr<PlantConfig> ReadPlant(const JsonField& f, const fs::path& base,
                                      const std::string& station_id) {
  if (absl::Status s = f.AllowOnlyKeys({"dsn", "station_id", "batch", "tls", "password_file",
                                        "max_backlog_age_s", "max_retry_interval_s"});
      !s.ok()) {
    return s;
  }
  PlantConfig c;
  absl::StatusOr<std::string> dsn = f.String("dsn");
  if (!dsn.ok()) return dsn.status();
  c.dsn = *dsn;
  absl::StatusOr<std::string> id = f.StringOr("station_id", station_id);
  if (!id.ok()) return id.status();
  if (id->empty()) return f.Error("station_id", "must not be empty");
  c.station_id = *id;
  // 10,000 cycles: Forwarder::Start's bound.
  absl::StatusOr<std::int64_t> batch = f.IntegerOr("batch", c.batch);
  if (!batch.ok()) return batch.status();
  if (*batch < 1 || *batch > 10000) {
    return f.Error("batch", absl::StrCat("must be in [1, 10000], got ", *batch));
  }
  c.batch = static_cast<int>(*batch);
  // A week: an age beyond it is a unit mistake (milliseconds for seconds).
  absl::StatusOr<std::int64_t> age = f.IntegerOr("max_backlog_age_s", c.max_backlog_age.count());
  if (!age.ok()) return age.status();
  if (*age < 1 || *age > 604800) {
    return f.Error("max_backlog_age_s", absl::StrCat("must be in [1, 604800], got ", *age));
  }
  c.max_backlog_age = std::chrono::seconds(*age);
  // An hour between retries at most: a plant back from an outage is noticed within it.
  absl::StatusOr<std::int64_t> retry =
      f.IntegerOr("max_retry_interval_s",
                  std::chrono::duration_cast<std::chrono::seconds>(c.max_retry_interval).count());
  if (!retry.ok()) return retry.status();
  if (*retry < 1 || *retry > 3600) {
    return f.Error("max_retry_interval_s", absl::StrCat("must be in [1, 3600], got ", *retry));
  }
  c.max_retry_interval = std::chrono::seconds(*retry);
  if (f.Has("password_file")) {
    absl::StatusOr<std::string> path = f.String("password_file");
    if (!path.ok()) return path.status();
    absl::StatusOr<std::string> text = ReadTextFile(Resolve(base, *path));
    if (!text.ok()) return f.Error("password_file", std::string(text.status().message()));
    // The first line, as a password file written with `echo` ends with a newline.
    c.password = std::string(absl::StripTrailingAsciiWhitespace(text->substr(0, text->find('\n'))));
    if (c.password.empty()) {
      return f.Error("password_file", absl::StrCat("'", *path, "': no password on its first line"));
    }
  }
  if (f.Has("tls")) {
    absl::StatusOr<JsonField> tls = f.Object("tls");
    if (!tls.ok()) return tls.status();
    if (absl::Status s = tls->AllowOnlyKeys({"mode", "ca", "cert", "key"}); !s.ok()) return s;
    PlantTlsConfig t;
    absl::StatusOr<std::string> mode = tls->StringOr("mode", t.mode);
    if (!mode.ok()) return mode.status();
    if (*mode != "disable" && *mode != "require" && *mode != "verify-ca" &&
        *mode != "verify-full") {
      return tls->Error(
          "mode",
          absl::StrCat("must be disable, require, verify-ca or verify-full, got '", *mode, "'"));
    }
    t.mode = *mode;
    const std::pair<const char*, std::string*> files[] = {
        {"ca", &t.ca_path}, {"cert", &t.cert_path}, {"key", &t.key_path}};
    for (const auto& [key, slot] : files) {
      absl::StatusOr<std::string> path = tls->StringOr(key, "");
      if (!path.ok()) return path.status();
      if (path->empty()) continue;
      *slot = Resolve(base, *path);
      std::error_code ec;
      if (!fs::is_regular_file(*slot, ec)) {
        return tls->Error(key, absl::StrCat("'", *slot, "': no such file"));
      }
    }
    if (t.cert_path.empty() != t.key_path.empty()) {
      return tls->Error(t.cert_path.empty() ? "cert" : "key",
                        "cert and key go together (a client certificate)");
    }
    c.tls = t;
  }
  if (absl::StatusOr<std::string> conninfo = PlantConnectionString(c); !conninfo.ok()) {
    return f.Error("dsn", std::string(conninfo.status().message()));
  }
  return c;
}

constexpr char kListenForm[] = ": must be HOST:PORT with a port in 0..65535";

// HOST:PORT with a decimal port in 0..65535 (CheckListenAddress).
bool IsListenAddress(const std::string& address) {
  const size_t colon = address.rfind(':');
  const std::string port = colon == std::string::npos ? "" : address.substr(colon + 1);
  int value = 0;
  // gRPC takes a port beyond 65535 without complaint and listens on another one.
  const auto is_digit = [](char c) { return c >= '0' && c <= '9'; };
  // At most 5 digits (65535): a longer string cannot overflow SimpleAtoi into range.
  const bool digits =
      !port.empty() && port.size() <= 5 && std::all_of(port.begin(), port.end(), is_digit);
  return colon != 0 && digits && absl::SimpleAtoi(port, &value) && value <= 65535;
}

// The `web` object (docs/daemon.md, "Console"): where the console listens, its TLS (the
// shape of the top-level tls) and its pages' folder.
absl::StatusOr<WebConfig> ReadWeb(const JsonField& f, const fs::path& base) {
  if (absl::Status s = f.AllowOnlyKeys({"listen", "tls", "static_dir", "operator_token"}); !s.ok())
    return s;
  WebConfig c;
  absl::StatusOr<std::string> listen = f.String("listen");
  if (!listen.ok()) return listen.status();
  if (!IsListenAddress(*listen)) return f.Error("listen", QuoteInput(*listen) + kListenForm);
  c.listen = *listen;
  absl::StatusOr<std::string> dir = f.StringOr("static_dir", "");
  if (!dir.ok()) return dir.status();
  if (!dir->empty()) {
    c.static_dir = Resolve(base, *dir);
    std::error_code ec;
    if (!fs::is_directory(c.static_dir, ec)) {
      return f.Error("static_dir", absl::StrCat("'", c.static_dir, "': no such folder"));
    }
  }
  if (f.Has("tls")) {
    absl::StatusOr<JsonField> tls_field = f.Object("tls");
    if (!tls_field.ok()) return tls_field.status();
    absl::StatusOr<TlsConfig> tls = ReadTls(*tls_field, base);
    if (!tls.ok()) return tls.status();
    c.tls = *std::move(tls);
  }
  absl::StatusOr<std::string> operator_token = f.StringOr("operator_token", "");
  if (!operator_token.ok()) return operator_token.status();
  c.operator_token = *operator_token;
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

absl::Status CheckListenAddress(const std::string& address, const std::string& key) {
  if (IsListenAddress(address)) return absl::OkStatus();
  return absl::InvalidArgumentError(absl::StrCat(key, ": ", QuoteInput(address), kListenForm));
}

namespace {

// listen, log_level, auth_token and station_id of the file's root.
absl::Status ReadService(const JsonField& root, DaemonConfig* c) {
  absl::StatusOr<std::string> listen = root.StringOr("listen", c->listen);
  if (!listen.ok()) return listen.status();
  c->listen = *listen;
  absl::StatusOr<std::string> level = root.StringOr("log_level", c->log_level);
  if (!level.ok()) return level.status();
  if (*level != "debug" && *level != "info" && *level != "warning" && *level != "error") {
    return root.Error("log_level",
                      absl::StrCat("must be debug, info, warning or error, got '", *level, "'"));
  }
  c->log_level = *level;
  absl::StatusOr<std::string> token = root.StringOr("auth_token", "");
  if (!token.ok()) return token.status();
  c->auth_token = *token;
  absl::StatusOr<std::string> id = root.StringOr("station_id", "station");
  if (!id.ok()) return id.status();
  c->core.station_id = *id;
  return absl::OkStatus();
}

// The station, car model and data files, relative to the file's folder `base`; the database
// relative to the data root.
absl::Status ReadPaths(const JsonField& root, const fs::path& base, StationCoreConfig* core) {
  absl::StatusOr<std::string> station = root.String("station");
  if (!station.ok()) return station.status();
  core->station_path = Resolve(base, *station);
  absl::StatusOr<std::vector<JsonField>> cars = root.Array("car_models");
  if (!cars.ok()) return cars.status();
  for (const JsonField& f : *cars) {
    absl::StatusOr<std::string> car = f.AsString();
    if (!car.ok()) return car.status();
    core->car_model_paths.push_back(Resolve(base, *car));
  }
  absl::StatusOr<std::string> data_root = root.String("data_root");
  if (!data_root.ok()) return data_root.status();
  core->data_root = Resolve(base, *data_root);
  absl::StatusOr<std::string> db = root.StringOr("db", "linecal.db");
  if (!db.ok()) return db.status();
  core->db_path = fs::path(*db).is_absolute() ? *db : (fs::path(core->data_root) / *db).string();
  return absl::OkStatus();
}

// The `source` section (absent: the simulator).
absl::Status ReadSource(const JsonField& root, const fs::path& base, StationCoreConfig* core) {
  if (!root.Has("source")) return absl::OkStatus();
  absl::StatusOr<JsonField> source = root.Object("source");
  if (!source.ok()) return source.status();
  absl::StatusOr<std::string> type = source->String("type");
  if (!type.ok()) return type.status();
  if (absl::Status s = *type == "live"        ? source->AllowOnlyKeys({"type", "sensors"})
                       : *type == "simulator" ? source->AllowOnlyKeys({"type", "moved_boards"})
                                              : source->AllowOnlyKeys({"type", "capture"});
      !s.ok()) {
    return s;
  }
  if (*type == "live") {
    core->source = CycleSource::kLive;
    absl::StatusOr<JsonField> sensors = source->Object("sensors");
    if (!sensors.ok()) return sensors.status();
    for (const auto& [name, value] : sensors->node().items()) {
      absl::StatusOr<JsonField> entry = sensors->Object(name);
      if (!entry.ok()) return entry.status();
      absl::StatusOr<SourceConfig> sensor = ParseSensorSource(*entry, base);
      if (!sensor.ok()) return sensor.status();
      core->live_sources[name] = *std::move(sensor);
    }
  } else if (*type == "simulator") {
    core->source = CycleSource::kSimulator;
    if (source->Has("moved_boards")) {
      absl::StatusOr<std::vector<SimulatedBoardMove>> moves = ParseSimulatedMoves(*source);
      if (!moves.ok()) return moves.status();
      core->simulated_moves = *std::move(moves);
    }
  } else if (*type == "replay") {
    core->source = CycleSource::kReplay;
    absl::StatusOr<std::string> capture = source->String("capture");
    if (!capture.ok()) return capture.status();
    if (absl::Status s = CheckReplayInside(*source, core->data_root, *capture); !s.ok()) {
      return s;
    }
    core->replay_capture = *capture;
  } else {
    return source->Error(
        "type", absl::StrCat("must be 'simulator', 'replay' or 'live', got '", *type, "'"));
  }
  return absl::OkStatus();
}

// vin_check_digit, frames_per_sensor and busy_timeout_ms.
absl::Status ReadCycleLimits(const JsonField& root, StationCoreConfig* core) {
  absl::StatusOr<bool> check = root.BoolOr("vin_check_digit", true);
  if (!check.ok()) return check.status();
  core->vin_check_digit = *check;
  absl::StatusOr<std::int64_t> frames = root.IntegerOr("frames_per_sensor", 1);
  if (!frames.ok()) return frames.status();
  if (*frames < 1 || *frames > 100) return root.Error("frames_per_sensor", "must be in [1, 100]");
  core->default_frames_per_sensor = static_cast<int>(*frames);
  absl::StatusOr<std::int64_t> busy = root.IntegerOr("busy_timeout_ms", 5000);
  if (!busy.ok()) return busy.status();
  if (*busy < 0 || *busy > 600000) return root.Error("busy_timeout_ms", "must be in [0, 600000]");
  core->busy_timeout = std::chrono::milliseconds(*busy);
  return absl::OkStatus();
}

// The optional sections: tls, deadlines_ms, input_budget, plant and web.
absl::Status ReadSections(const JsonField& root, const fs::path& base, DaemonConfig* c) {
  if (root.Has("tls")) {
    absl::StatusOr<JsonField> tls_field = root.Object("tls");
    if (!tls_field.ok()) return tls_field.status();
    absl::StatusOr<TlsConfig> tls = ReadTls(*tls_field, base);
    if (!tls.ok()) return tls.status();
    c->tls = *std::move(tls);
  }
  if (root.Has("deadlines_ms")) {
    absl::StatusOr<JsonField> deadlines = root.Object("deadlines_ms");
    if (!deadlines.ok()) return deadlines.status();
    if (absl::Status s = deadlines->AllowOnlyKeys({"acquire", "calibrate"}); !s.ok()) return s;
    absl::StatusOr<std::chrono::milliseconds> acquire =
        Milliseconds(*deadlines, "acquire", c->core.acquire_deadline);
    if (!acquire.ok()) return acquire.status();
    absl::StatusOr<std::chrono::milliseconds> calibrate =
        Milliseconds(*deadlines, "calibrate", c->core.calibrate_deadline);
    if (!calibrate.ok()) return calibrate.status();
    c->core.acquire_deadline = *acquire;
    c->core.calibrate_deadline = *calibrate;
  }
  if (root.Has("input_budget")) {
    absl::StatusOr<JsonField> budget_field = root.Object("input_budget");
    if (!budget_field.ok()) return budget_field.status();
    absl::StatusOr<InputBudget> budget = ReadInputBudget(*budget_field);
    if (!budget.ok()) return budget.status();
    c->input_budget = *budget;
  }
  if (root.Has("plant")) {
    absl::StatusOr<JsonField> plant_field = root.Object("plant");
    if (!plant_field.ok()) return plant_field.status();
    absl::StatusOr<PlantConfig> plant = ReadPlant(*plant_field, base, c->core.station_id);
    if (!plant.ok()) return plant.status();
    c->core.plant = *std::move(plant);
  }
  if (root.Has("web")) {
    absl::StatusOr<JsonField> web_field = root.Object("web");
    if (!web_field.ok()) return web_field.status();
    absl::StatusOr<WebConfig> web = ReadWeb(*web_field, base);
    if (!web.ok()) return web.status();
    c->web = *std::move(web);
    // One token, one role: a login with it could not say which session it opens.
    if (!c->web->operator_token.empty() && c->web->operator_token == c->auth_token) {
      return web_field->Error("operator_token", "must differ from auth_token");
    }
  }
  return absl::OkStatus();
}

}  // namespace

absl::StatusOr<DaemonConfig> ReadDaemonConfig(const std::string& path) {
  absl::StatusOr<JsonDocument> doc = JsonDocument::FromFile(path);
  if (!doc.ok()) return doc.status();
  absl::StatusOr<JsonField> root = doc->Root();
  if (!root.ok()) return root.status();
  if (absl::Status s = root->AllowOnlyKeys(
          {"listen", "log_level", "auth_token", "station_id", "station", "car_models", "data_root",
           "db", "source", "vin_check_digit", "frames_per_sensor", "busy_timeout_ms", "tls",
           "deadlines_ms", "input_budget", "plant", "web"});
      !s.ok()) {
    return s;
  }
  const fs::path base = fs::path(path).parent_path();
  DaemonConfig c;
  if (absl::Status s = ReadService(*root, &c); !s.ok()) return s;
  if (absl::Status s = ReadPaths(*root, base, &c.core); !s.ok()) return s;
  if (absl::Status s = ReadSource(*root, base, &c.core); !s.ok()) return s;
  if (absl::Status s = ReadCycleLimits(*root, &c.core); !s.ok()) return s;
  if (absl::Status s = ReadSections(*root, base, &c); !s.ok()) return s;
  return c;
}

}  // namespace linecal
