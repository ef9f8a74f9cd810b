// The quality engineer's commands on the plant database (docs/plant.md): linecal plant
// migrate / cycles / yield / export. The database is found by --dsn or LINECAL_PLANT_DSN (a
// libpq connection string); a password by --password-file, the DSN, PGPASSWORD or ~/.pgpass.
// A password is never printed: errors name the server as host:port.
#include <cstdio>
#include <cstdlib>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "absl/strings/ascii.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "absl/time/time.h"
#include "daemon/plant/plant_db.h"
#include "station/io/json_reader.h"
#include "tools/cli/command_line.h"
#include "tools/linecal/commands.h"

namespace linecal::tools {
namespace {

std::vector<cli::OptionSpec> PlantOptions(std::vector<cli::OptionSpec> options) {
  options.push_back({"dsn", "DSN",
                     "the plant database, a libpq connection string "
                     "(default $LINECAL_PLANT_DSN)"});
  options.push_back({"password-file", "FILE", "the password, on the file's first line"});
  options.push_back({"json", "", "print JSON"});
  return options;
}

// The connection the options name. Errors name the flag; the database's errors name the
// server (never the password).
absl::StatusOr<std::unique_ptr<PlantDb>> ConnectPlant(const cli::CommandLine& cl) {
  const char* env_dsn = std::getenv("LINECAL_PLANT_DSN");
  const std::string dsn = cl.Get("dsn", env_dsn != nullptr ? env_dsn : "");
  if (dsn.empty()) {
    return absl::InvalidArgumentError("--dsn: not given and LINECAL_PLANT_DSN is not set");
  }
  if (cl.Has("password-file")) {
    absl::StatusOr<std::string> text = ReadTextFile(cl.Get("password-file"));
    if (!text.ok()) {
      return absl::InvalidArgumentError(absl::StrCat("--password-file: ", text.status().message()));
    }
    const std::string first_line = text->substr(0, text->find('\n'));
    const std::string password(absl::StripTrailingAsciiWhitespace(first_line));
    if (password.empty()) {
      return absl::InvalidArgumentError(
          absl::StrCat("--password-file: '", cl.Get("password-file"), "' holds no password"));
    }
    // libpq reads it from there (a password in the DSN itself still wins).
    setenv("PGPASSWORD", password.c_str(), 1);
  }
  return PlantDb::Connect(dsn);
}

// A failed call: bad input (2), as for a daemon that does not answer (cmd_cycle.cc).
int Failed(const std::string& command, const absl::Status& s) {
  return cli::BadInput(command, std::string(s.message()));
}

// --since: a date (UTC midnight) or an RFC 3339 time.
absl::StatusOr<int64_t> ParseSince(const cli::CommandLine& cl) {
  const std::string text = cl.Get("since");
  absl::Time t;
  std::string ignored;
  if (absl::ParseTime("%Y-%m-%d", text, absl::UTCTimeZone(), &t, &ignored) ||
      absl::ParseTime(absl::RFC3339_full, text, absl::UTCTimeZone(), &t, &ignored)) {
    return absl::ToUnixNanos(t);
  }
  return absl::InvalidArgumentError(absl::StrCat(
      "--since: '", text, "' is neither a date (2026-11-02) nor a time (2026-11-02T08:00:00Z)"));
}

std::string Time(int64_t ns) {
  return absl::FormatTime("%Y-%m-%d %H:%M:%S", absl::FromUnixNanos(ns), absl::UTCTimeZone());
}

std::string Rfc3339(int64_t ns) {
  return absl::FormatTime(absl::RFC3339_full, absl::FromUnixNanos(ns), absl::UTCTimeZone());
}

// The station's JSON text as JSON (the text as a string should it not parse).
nlohmann::json Embedded(const std::string& text) {
  if (text.empty()) return nullptr;
  nlohmann::json parsed = nlohmann::json::parse(text, nullptr, false);
  return parsed.is_discarded() ? nlohmann::json(text) : parsed;
}

nlohmann::json MountingJson(const MountingValues& m) {
  return {{"yaw_deg", m.yaw_deg},   {"pitch_deg", m.pitch_deg},
          {"roll_deg", m.roll_deg}, {"x_m", m.x_m},
          {"y_m", m.y_m},           {"z_m", m.z_m}};
}

nlohmann::json SensorJson(const StoredSensorResult& s) {
  nlohmann::json j = {{"sensor", s.sensor},
                      {"kind", SensorKindName(s.kind)},
                      {"verdict", VerdictName(s.verdict)},
                      {"reason", s.reason},
                      {"message", s.message},
                      {"T_car_sensor", s.T_car_sensor},
                      {"measured", MountingJson(s.measured)},
                      {"deviation", MountingJson(s.deviation)},
                      {"sigma", MountingJson(s.sigma)},
                      {"residual_rms", s.residual_rms},
                      {"features_used", s.features_used},
                      {"ground_homography", s.ground_homography},
                      {"ranging", Embedded(s.ranging_json)},
                      {"elapsed_ns", s.elapsed_ns}};
  if (s.vanishing_point_u_px && s.vanishing_point_v_px) {
    j["vanishing_point_px"] = {*s.vanishing_point_u_px, *s.vanishing_point_v_px};
  }
  return j;
}

nlohmann::json RecordJson(const PlantCycleRecord& r) {
  const StoredCycle& c = r.cycle;
  nlohmann::json sensors = nlohmann::json::array();
  for (const StoredSensorResult& s : c.sensors) sensors.push_back(SensorJson(s));
  return {{"station_id", r.station_id},
          {"cycle_id", c.id},
          {"vin", c.vin},
          {"car_model_id", c.car_model_id},
          {"state", CycleStateName(c.state)},
          {"verdict", VerdictName(c.verdict)},
          {"reason", c.reason},
          {"started", Rfc3339(c.started_ns)},
          {"ended", Rfc3339(c.ended_ns)},
          {"started_ns", c.started_ns},
          {"ended_ns", c.ended_ns},
          {"capture_path", c.capture_path},
          {"request", Embedded(c.request_json)},
          {"received", Rfc3339(r.received_ns)},
          {"sensors", sensors}};
}

void PrintJson(const nlohmann::json& j) {
  std::printf("%s\n", j.dump(2, ' ', false, nlohmann::json::error_handler_t::replace).c_str());
}

std::string Or(const std::string& text, const char* dash = "-") {
  return text.empty() ? dash : text;
}

void PrintCyclesTable(const std::vector<PlantCycleRecord>& records) {
  std::printf("%-12s %8s  %-19s  %-17s  %-12s %-9s %-7s %s\n", "STATION", "CYCLE", "STARTED (UTC)",
              "VIN", "CAR MODEL", "STATE", "VERDICT", "REASON / SENSORS");
  for (const PlantCycleRecord& r : records) {
    const StoredCycle& c = r.cycle;
    std::vector<std::string> sensors;
    for (const StoredSensorResult& s : c.sensors) {
      sensors.push_back(absl::StrCat(s.sensor, ":", Or(VerdictName(s.verdict)),
                                     s.reason.empty() ? "" : absl::StrCat("(", s.reason, ")")));
    }
    const std::string details = absl::StrCat(c.reason.empty() ? "" : absl::StrCat(c.reason, "; "),
                                             absl::StrJoin(sensors, " "));
    std::printf("%-12s %8lld  %-19s  %-17s  %-12s %-9s %-7s %s\n", r.station_id.c_str(),
                static_cast<long long>(c.id), Time(c.started_ns).c_str(), c.vin.c_str(),
                c.car_model_id.c_str(), CycleStateName(c.state), Or(VerdictName(c.verdict)).c_str(),
                details.c_str());
  }
}

double YieldPercent(const YieldRow& r) {
  return r.first_attempts > 0 ? 100.0 * static_cast<double>(r.passed) / r.first_attempts : 0;
}

// CSV: one line per sensor result (a cycle without results: one line, sensor columns
// empty), RFC 4180 quoting.
std::string Csv(const std::string& field) {
  if (field.find_first_of(",\"\r\n") == std::string::npos) return field;
  std::string quoted = "\"";
  for (char ch : field) {
    if (ch == '"') quoted += '"';
    quoted += ch;
  }
  return quoted + "\"";
}

std::string Number(double v) { return absl::StrFormat("%.17g", v); }

void AppendMounting(const MountingValues& m, std::vector<std::string>* out) {
  for (double v : {m.yaw_deg, m.pitch_deg, m.roll_deg, m.x_m, m.y_m, m.z_m}) {
    out->push_back(Number(v));
  }
}

void PrintCsv(const std::vector<PlantCycleRecord>& records) {
  std::vector<std::string> header = {"station_id",     "cycle_id",     "vin",    "car_model_id",
                                     "state",          "verdict",      "reason", "started",
                                     "ended",          "capture_path", "sensor", "kind",
                                     "sensor_verdict", "sensor_reason"};
  for (const char* group : {"measured", "deviation", "sigma"}) {
    for (const char* axis : {"yaw_deg", "pitch_deg", "roll_deg", "x_m", "y_m", "z_m"}) {
      header.push_back(absl::StrCat(group, "_", axis));
    }
  }
  header.insert(header.end(), {"residual_rms", "features_used", "elapsed_ns"});
  std::printf("%s\n", absl::StrJoin(header, ",").c_str());
  for (const PlantCycleRecord& r : records) {
    const StoredCycle& c = r.cycle;
    const std::vector<std::string> cycle = {
        r.station_id,   absl::StrCat(c.id),      c.vin,
        c.car_model_id, CycleStateName(c.state), VerdictName(c.verdict),
        c.reason,       Rfc3339(c.started_ns),   Rfc3339(c.ended_ns),
        c.capture_path};
    std::vector<std::vector<std::string>> lines;
    for (const StoredSensorResult& s : c.sensors) {
      std::vector<std::string> line = cycle;
      line.insert(line.end(), {s.sensor, SensorKindName(s.kind), VerdictName(s.verdict), s.reason});
      AppendMounting(s.measured, &line);
      AppendMounting(s.deviation, &line);
      AppendMounting(s.sigma, &line);
      line.insert(line.end(), {Number(s.residual_rms), absl::StrCat(s.features_used),
                               absl::StrCat(s.elapsed_ns)});
      lines.push_back(std::move(line));
    }
    if (lines.empty()) {
      lines.push_back(cycle);
      lines.back().resize(header.size());
    }
    for (std::vector<std::string>& line : lines) {
      for (std::string& field : line) field = Csv(field);
      std::printf("%s\n", absl::StrJoin(line, ",").c_str());
    }
  }
}

}  // namespace

int RunPlantMigrate(const Args& args) {
  cli::CommandLine cl("linecal plant migrate [--dsn DSN] [--password-file FILE] [--json]",
                      "Creates or upgrades the plant database's schema and its roles "
                      "(linecal_station, linecal_report). Needs the DBA's role.",
                      PlantOptions({}));
  if (const std::optional<int> exit = cli::ParseOrExit(cl, "plant migrate", args)) return *exit;
  absl::StatusOr<std::unique_ptr<PlantDb>> db = ConnectPlant(cl);
  if (!db.ok()) return Failed("plant migrate", db.status());
  const absl::StatusOr<int> before = (*db)->SchemaVersion();
  if (!before.ok()) return Failed("plant migrate", before.status());
  if (absl::Status s = (*db)->Migrate(); !s.ok()) return Failed("plant migrate", s);
  if (cl.Has("json")) {
    PrintJson({{"server", (*db)->server()},
               {"schema_version_before", *before},
               {"schema_version", PlantDb::kSchemaVersion}});
  } else if (*before == PlantDb::kSchemaVersion) {
    std::printf("plant database %s: schema version %d, up to date\n", (*db)->server().c_str(),
                *before);
  } else {
    std::printf("plant database %s: schema version %d -> %d\n", (*db)->server().c_str(), *before,
                PlantDb::kSchemaVersion);
  }
  return cli::kExitOk;
}

int RunPlantCycles(const Args& args) {
  cli::CommandLine cl("linecal plant cycles --vin VIN [--dsn DSN] [--json]",
                      "Every attempt on a car at every station, newest first, with its sensors.",
                      PlantOptions({{"vin", "VIN", "the car", true}}));
  if (const std::optional<int> exit = cli::ParseOrExit(cl, "plant cycles", args)) return *exit;
  absl::StatusOr<std::unique_ptr<PlantDb>> db = ConnectPlant(cl);
  if (!db.ok()) return Failed("plant cycles", db.status());
  if (absl::Status s = (*db)->CheckSchema(); !s.ok()) return Failed("plant cycles", s);
  absl::StatusOr<std::vector<PlantCycleRecord>> records = (*db)->CyclesByVin(cl.Get("vin"));
  if (!records.ok()) return Failed("plant cycles", records.status());
  if (cl.Has("json")) {
    nlohmann::json j = nlohmann::json::array();
    for (const PlantCycleRecord& r : *records) j.push_back(RecordJson(r));
    PrintJson(j);
  } else {
    PrintCyclesTable(*records);
  }
  // No attempt at all: a negative answer, as for an unknown cycle (cycle show).
  return records->empty() ? cli::kExitNegative : cli::kExitOk;
}

int RunPlantYield(const Args& args) {
  cli::CommandLine cl(
      "linecal plant yield --since DATE [--station S] [--car-model M] [--top N] [--dsn DSN] "
      "[--json]",
      "First-pass yield per station, car model and sensor: of the cars whose first attempt at "
      "a station started since DATE, the share that passed on it; and the top failure reasons "
      "per sensor on those first attempts.",
      PlantOptions({{"since", "DATE", "2026-11-02 (UTC) or 2026-11-02T08:00:00Z", true},
                    {"station", "S", "only this station"},
                    {"car-model", "M", "only this car model"},
                    {"top", "N", "failure reasons per sensor (default 3, at most 100)"}}));
  if (const std::optional<int> exit = cli::ParseOrExit(cl, "plant yield", args)) return *exit;
  const absl::StatusOr<int64_t> since = ParseSince(cl);
  if (!since.ok()) return Failed("plant yield", since.status());
  const absl::StatusOr<int> top = cl.GetInt("top", 3);
  if (!top.ok() || *top < 1 || *top > 100) {
    return cli::BadInput("plant yield",
                         absl::StrCat("--top: '", cl.Get("top"), "': must be in [1, 100]"));
  }
  absl::StatusOr<std::unique_ptr<PlantDb>> db = ConnectPlant(cl);
  if (!db.ok()) return Failed("plant yield", db.status());
  if (absl::Status s = (*db)->CheckSchema(); !s.ok()) return Failed("plant yield", s);
  const absl::StatusOr<YieldReport> report =
      (*db)->Yield({*since, cl.Get("station"), cl.Get("car-model"), *top});
  if (!report.ok()) return Failed("plant yield", report.status());
  if (cl.Has("json")) {
    nlohmann::json rows = nlohmann::json::array(), reasons = nlohmann::json::array();
    for (const YieldRow& r : report->rows) {
      rows.push_back({{"station_id", r.station_id},
                      {"car_model_id", r.car_model_id},
                      {"sensor", r.sensor},
                      {"first_attempts", r.first_attempts},
                      {"passed", r.passed},
                      {"yield_percent", YieldPercent(r)}});
    }
    for (const FailureReason& f : report->reasons) {
      reasons.push_back({{"sensor", f.sensor}, {"reason", f.reason}, {"count", f.count}});
    }
    PrintJson({{"since", Rfc3339(*since)}, {"yield", rows}, {"failure_reasons", reasons}});
    return cli::kExitOk;
  }
  std::printf("first-pass yield since %s UTC\n", Time(*since).c_str());
  std::printf("%-12s %-12s %-20s %14s %7s %7s\n", "STATION", "CAR MODEL", "SENSOR",
              "FIRST ATTEMPTS", "PASSED", "YIELD");
  for (const YieldRow& r : report->rows) {
    std::printf("%-12s %-12s %-20s %14lld %7lld %6.1f%%\n", r.station_id.c_str(),
                r.car_model_id.c_str(), Or(r.sensor, "(cycle)").c_str(),
                static_cast<long long>(r.first_attempts), static_cast<long long>(r.passed),
                YieldPercent(r));
  }
  std::printf("\ntop failure reasons on first attempts\n%-20s %-32s %6s\n", "SENSOR", "REASON",
              "COUNT");
  for (const FailureReason& f : report->reasons) {
    std::printf("%-20s %-32s %6lld\n", f.sensor.c_str(), Or(f.reason).c_str(),
                static_cast<long long>(f.count));
  }
  return cli::kExitOk;
}

int RunPlantExport(const Args& args) {
  cli::CommandLine cl(
      "linecal plant export --since DATE [--format csv|json] [--limit N] [--dsn DSN]",
      "Cycles started since DATE at every station with their sensor results, oldest first: "
      "CSV (one line per sensor result) or JSON (one object per cycle).",
      PlantOptions({{"since", "DATE", "2026-11-02 (UTC) or 2026-11-02T08:00:00Z", true},
                    {"format", "csv|json", "the output (default csv)"},
                    {"limit", "N", "at most N cycles (default and most: 1000000)"}}));
  if (const std::optional<int> exit = cli::ParseOrExit(cl, "plant export", args)) return *exit;
  const absl::StatusOr<int64_t> since = ParseSince(cl);
  if (!since.ok()) return Failed("plant export", since.status());
  const std::string format = cl.Has("json") ? "json" : cl.Get("format", "csv");
  if (format != "csv" && format != "json") {
    return cli::BadInput("plant export",
                         absl::StrCat("--format: '", format, "': must be csv or json"));
  }
  const absl::StatusOr<int> limit = cl.GetInt("limit", 1000000);
  if (!limit.ok() || *limit < 1 || *limit > 1000000) {
    return cli::BadInput("plant export",
                         absl::StrCat("--limit: '", cl.Get("limit"), "': must be in [1, 1000000]"));
  }
  absl::StatusOr<std::unique_ptr<PlantDb>> db = ConnectPlant(cl);
  if (!db.ok()) return Failed("plant export", db.status());
  if (absl::Status s = (*db)->CheckSchema(); !s.ok()) return Failed("plant export", s);
  const absl::StatusOr<std::vector<PlantCycleRecord>> records = (*db)->CyclesSince(*since, *limit);
  if (!records.ok()) return Failed("plant export", records.status());
  if (format == "json") {
    nlohmann::json j = nlohmann::json::array();
    for (const PlantCycleRecord& r : *records) j.push_back(RecordJson(r));
    PrintJson(j);
  } else {
    PrintCsv(*records);
  }
  if (static_cast<int>(records->size()) == *limit) {
    std::fprintf(stderr, "linecal plant export: stopped at --limit %d cycles\n", *limit);
  }
  return cli::kExitOk;
}

}  // namespace linecal::tools
