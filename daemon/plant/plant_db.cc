#include "daemon/plant/plant_db.h"

#include <libpq-fe.h>
#include <sys/socket.h>

#include <algorithm>
#include <cmath>
#include <condition_variable>
#include <cstdlib>
#include <map>
#include <nlohmann/json.hpp>
#include <pqxx/pqxx>
#include <set>
#include <thread>
#include <utility>

#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "absl/strings/str_replace.h"
#include "absl/strings/str_split.h"

namespace linecal {

struct PlantDb::Connection {
  explicit Connection(const std::string& conninfo) : conn(conninfo) {}
  pqxx::connection conn;
};

namespace {

// Migrations, in order: kMigrations[v - 1] brings a schema at version v - 1 to v. Never edit
// one that shipped; add the next. Roles are cluster-wide, so they may exist already (another
// database of the same cluster).
constexpr const char* kMigrations[] = {
    R"sql(
CREATE TABLE stations (
  station_id text PRIMARY KEY,
  first_seen timestamptz NOT NULL DEFAULT now());

CREATE TABLE cycles (
  station_id   text   NOT NULL REFERENCES stations,
  cycle_id     bigint NOT NULL,
  vin          text   NOT NULL,
  car_model    text   NOT NULL,
  state        text   NOT NULL CHECK (state IN ('done', 'cancelled', 'aborted')),
  verdict      text   NOT NULL CHECK (verdict IN ('', 'pass', 'fail', 'error')),
  reason       text   NOT NULL,
  started_ns   bigint NOT NULL,
  ended_ns     bigint NOT NULL,
  started_at   timestamptz GENERATED ALWAYS AS (to_timestamp(started_ns / 1e9::float8)) STORED,
  ended_at     timestamptz GENERATED ALWAYS AS (to_timestamp(ended_ns / 1e9::float8)) STORED,
  capture_path text   NOT NULL,
  request_json jsonb,
  received_at  timestamptz NOT NULL DEFAULT now(),
  PRIMARY KEY (station_id, cycle_id));
-- linecal plant cycles --vin, and the first attempt of a VIN at a station (yield).
CREATE INDEX cycles_vin ON cycles (vin, station_id, cycle_id);
-- linecal plant export / yield --since, with and without --station.
CREATE INDEX cycles_started ON cycles (started_at);
CREATE INDEX cycles_station_started ON cycles (station_id, started_at);

CREATE TABLE sensor_results (
  station_id text   NOT NULL,
  cycle_id   bigint NOT NULL,
  sensor     text   NOT NULL,
  kind       text   NOT NULL,
  verdict    text   NOT NULL CHECK (verdict IN ('', 'pass', 'fail', 'error')),
  reason     text   NOT NULL,
  message    text   NOT NULL,
  t_car_sensor float8[],  -- 16 values, row-major; NULL when not solved
  measured_yaw_deg float8 NOT NULL, measured_pitch_deg float8 NOT NULL,
  measured_roll_deg float8 NOT NULL, measured_x_m float8 NOT NULL,
  measured_y_m float8 NOT NULL, measured_z_m float8 NOT NULL,
  deviation_yaw_deg float8 NOT NULL, deviation_pitch_deg float8 NOT NULL,
  deviation_roll_deg float8 NOT NULL, deviation_x_m float8 NOT NULL,
  deviation_y_m float8 NOT NULL, deviation_z_m float8 NOT NULL,
  sigma_yaw_deg float8 NOT NULL, sigma_pitch_deg float8 NOT NULL,
  sigma_roll_deg float8 NOT NULL, sigma_x_m float8 NOT NULL,
  sigma_y_m float8 NOT NULL, sigma_z_m float8 NOT NULL,
  residual_rms  float8 NOT NULL,
  features_used integer NOT NULL,
  vanishing_point_u_px float8,
  vanishing_point_v_px float8,
  ground_homography float8[],  -- cameras: 9 values, row-major
  ranging jsonb,               -- cameras: the ranging check
  elapsed_ns bigint NOT NULL,
  PRIMARY KEY (station_id, cycle_id, sensor),
  FOREIGN KEY (station_id, cycle_id) REFERENCES cycles);

CREATE TABLE events (
  station_id text   NOT NULL,
  cycle_id   bigint NOT NULL,
  sequence   bigint NOT NULL,
  time_ns    bigint NOT NULL,
  time_at    timestamptz GENERATED ALWAYS AS (to_timestamp(time_ns / 1e9::float8)) STORED,
  type       text   NOT NULL,
  sensor     text   NOT NULL,
  detail     text   NOT NULL,
  verdict    text   NOT NULL CHECK (verdict IN ('', 'pass', 'fail', 'error')),
  PRIMARY KEY (station_id, cycle_id, sequence),
  FOREIGN KEY (station_id, cycle_id) REFERENCES cycles);

DO $$
BEGIN
  IF NOT EXISTS (SELECT FROM pg_roles WHERE rolname = 'linecal_station') THEN
    CREATE ROLE linecal_station NOLOGIN;
  END IF;
  IF NOT EXISTS (SELECT FROM pg_roles WHERE rolname = 'linecal_report') THEN
    CREATE ROLE linecal_report NOLOGIN;
  END IF;
END $$;
GRANT USAGE ON SCHEMA public TO linecal_station, linecal_report;
-- Stations only add rows; RETURNING cycle_id tells ApplyBatch which cycles were new.
GRANT INSERT ON stations, cycles, sensor_results, events TO linecal_station;
GRANT SELECT (station_id, cycle_id) ON cycles TO linecal_station;
GRANT SELECT ON schema_migrations TO linecal_station, linecal_report;
GRANT SELECT ON stations, cycles, sensor_results, events TO linecal_report;
)sql",
    // 2: each sensor's target boards (the station store's board_results, its schema 3).
    R"sql(
CREATE TABLE board_results (
  station_id     text    NOT NULL,
  cycle_id       bigint  NOT NULL,
  sensor         text    NOT NULL,
  board          text    NOT NULL,
  frames         integer NOT NULL,
  frames_found   integer NOT NULL,
  frames_partial integer NOT NULL,
  residual_rms   float8,  -- NULL when the board did not enter a solve
  PRIMARY KEY (station_id, cycle_id, sensor, board),
  FOREIGN KEY (station_id, cycle_id, sensor) REFERENCES sensor_results);
GRANT INSERT ON board_results TO linecal_station;
GRANT SELECT ON board_results TO linecal_report;
)sql",
};
constexpr int kMigrationCount = static_cast<int>(std::size(kMigrations));
static_assert(kMigrationCount == PlantDb::kSchemaVersion);

// Serialises concurrent `linecal plant migrate` runs (any 64-bit key of our own).
constexpr int64_t kMigrationLockKey = 0x6c696e6563616c;  // "linecal"

// The parsed connection string: every keyword given, for rebuilding it and naming the server.
using ConnOptions = std::map<std::string, std::string>;

absl::StatusOr<ConnOptions> ParseDsn(const std::string& dsn) {
  char* error = nullptr;
  PQconninfoOption* parsed = PQconninfoParse(dsn.c_str(), &error);
  if (parsed == nullptr) {
    std::string why(error != nullptr ? absl::StripAsciiWhitespace(error) : "out of memory");
    PQfreemem(error);
    // libpq quotes the text around the mistake, which may be the password.
    if (absl::StrContains(absl::AsciiStrToLower(dsn), "password") || absl::StrContains(dsn, "@")) {
      why = "libpq could not parse it (details withheld: it holds a password)";
    }
    return absl::InvalidArgumentError(
        absl::StrCat("malformed plant database connection string: ", why));
  }
  ConnOptions options;
  for (const PQconninfoOption* o = parsed; o->keyword != nullptr; ++o) {
    if (o->val != nullptr) options[o->keyword] = o->val;
  }
  PQconninfoFree(parsed);
  return options;
}

std::string Getenv(const char* name) {
  const char* value = std::getenv(name);
  return value != nullptr ? value : "";
}

// "host:port" as libpq will use it: the DSN's, else PGHOST/PGPORT, else libpq's defaults.
std::string ServerName(const ConnOptions& o) {
  auto get = [&](const char* key, const char* env, const char* fallback) {
    auto it = o.find(key);
    if (it != o.end() && !it->second.empty()) return it->second;
    std::string value = Getenv(env);
    return value.empty() ? std::string(fallback) : value;
  };
  std::string host = get("host", "PGHOST", "");
  if (host.empty()) host = get("hostaddr", "PGHOSTADDR", "/var/run/postgresql");
  return absl::StrCat(host, ":", get("port", "PGPORT", "5432"));
}

// A keyword/value connection string from the parsed one, with libpq's connect_timeout
// unless the DSN has its own.
std::string Conninfo(ConnOptions o, const PlantDbOptions& options) {
  if (!o.count("connect_timeout")) {
    const auto seconds = std::chrono::ceil<std::chrono::seconds>(options.connect_timeout);
    o["connect_timeout"] = absl::StrCat(std::max<int64_t>(2, seconds.count()));
  }
  std::vector<std::string> parts;
  for (const auto& [key, value] : o) {
    parts.push_back(
        absl::StrCat(key, "='", absl::StrReplaceAll(value, {{"\\", "\\\\"}, {"'", "\\'"}}), "'"));
  }
  return absl::StrJoin(parts, " ");
}

// libpq's or the server's message, first line only, with the password (if any) masked.
std::string CleanMessage(const std::string& what, const std::string& password) {
  std::string line(absl::StripAsciiWhitespace(what.substr(0, what.find('\n'))));
  if (!password.empty()) absl::StrReplaceAll({{password, "****"}}, &line);
  return line;
}

absl::Status ConnectError(const std::string& what, const std::string& server) {
  const std::string message = absl::StrCat("plant database ", server, ": ", what);
  if (absl::StrContains(what, "authentication failed") ||
      absl::StrContains(what, "no password supplied") ||
      absl::StrContains(what, "no pg_hba.conf entry") ||
      (absl::StrContains(what, "role \"") && absl::StrContains(what, "does not exist")) ||
      absl::StrContains(what, "permission denied")) {
    return absl::PermissionDeniedError(message);
  }
  if (absl::StrContains(what, "database \"") && absl::StrContains(what, "does not exist")) {
    return absl::NotFoundError(message);
  }
  if (absl::StrContains(what, "invalid ") && absl::StrContains(what, " value")) {
    return absl::InvalidArgumentError(message);  // e.g. an unknown sslmode
  }
  return absl::UnavailableError(message);
}

// The status of an error a statement raised, by SQLSTATE class (PostgreSQL appendix A).
absl::Status SqlError(const pqxx::sql_error& e, const std::string& message) {
  // libpqxx 6 leaves the SQLSTATE empty on some paths (exec_params0); the server's wording
  // for a missing privilege is fixed, so fall back to it there.
  const std::string state = !e.sqlstate().empty()                             ? e.sqlstate()
                            : absl::StrContains(message, "permission denied") ? "42501"
                                                                              : "";
  const std::string cls = state.substr(0, 2);
  if (state == "42501" || cls == "28") return absl::PermissionDeniedError(message);
  if (cls == "08" || cls == "40" || cls == "53" || cls == "57") {
    // connection lost, conflict, out of resources, cancelled (statement_timeout), shutdown
    return absl::UnavailableError(message);
  }
  if (state == "3D000") return absl::NotFoundError(message);
  return absl::InternalError(absl::StrCat(message, " (SQLSTATE ", state, ")"));
}

// Literals for the multi-row INSERTs of ApplyBatch (one statement per table per batch:
// a round trip per row would cap catch-up at a few hundred cycles per second).
std::string Float(double v) {
  if (std::isnan(v)) return "'NaN'";
  if (std::isinf(v)) return v > 0 ? "'Infinity'" : "'-Infinity'";
  return absl::StrFormat("%.17g", v);  // exact: 17 significant digits round-trip a double
}

std::string FloatArray(const pqxx::work& tx, const std::vector<double>& values) {
  if (values.empty()) return "NULL";
  std::vector<std::string> parts;
  for (double v : values) {
    parts.push_back(std::isnan(v)   ? "NaN"
                    : std::isinf(v) ? (v > 0 ? "Infinity" : "-Infinity")
                                    : absl::StrFormat("%.17g", v));
  }
  return absl::StrCat(tx.quote(absl::StrCat("{", absl::StrJoin(parts, ","), "}")), "::float8[]");
}

// jsonb from the station's text: as is when it is JSON, else the text as a JSON string (a
// cycle the plant cannot store would block its station's outbox); NULL when empty.
std::string Jsonb(const pqxx::work& tx, const std::string& text) {
  if (text.empty()) return "NULL";
  constexpr auto kReplace = nlohmann::json::error_handler_t::replace;  // bad UTF-8
  const std::string json =
      nlohmann::json::accept(text) ? text : nlohmann::json(text).dump(-1, ' ', false, kReplace);
  return absl::StrCat(tx.quote(json), "::jsonb");
}

std::string Mounting(const MountingValues& m) {
  return absl::StrJoin({Float(m.yaw_deg), Float(m.pitch_deg), Float(m.roll_deg), Float(m.x_m),
                        Float(m.y_m), Float(m.z_m)},
                       ", ");
}

std::string CycleValues(const pqxx::work& tx, const std::string& station, const StoredCycle& c) {
  return absl::StrCat("(", tx.quote(station), ", ", c.id, ", ", tx.quote(c.vin), ", ",
                      tx.quote(c.car_model_id), ", ", tx.quote(CycleStateName(c.state)), ", ",
                      tx.quote(VerdictName(c.verdict)), ", ", tx.quote(c.reason), ", ",
                      c.started_ns, ", ", c.ended_ns, ", ", tx.quote(c.capture_path), ", ",
                      Jsonb(tx, c.request_json), ")");
}

std::string SensorValues(const pqxx::work& tx, const std::string& station, int64_t cycle_id,
                         const StoredSensorResult& s) {
  auto optional = [](const std::optional<double>& v) { return v ? Float(*v) : "NULL"; };
  return absl::StrCat("(", tx.quote(station), ", ", cycle_id, ", ", tx.quote(s.sensor), ", ",
                      tx.quote(SensorKindName(s.kind)), ", ", tx.quote(VerdictName(s.verdict)),
                      ", ", tx.quote(s.reason), ", ", tx.quote(s.message), ", ",
                      FloatArray(tx, s.T_car_sensor), ", ", Mounting(s.measured), ", ",
                      Mounting(s.deviation), ", ", Mounting(s.sigma), ", ", Float(s.residual_rms),
                      ", ", s.features_used, ", ", optional(s.vanishing_point_u_px), ", ",
                      optional(s.vanishing_point_v_px), ", ", FloatArray(tx, s.ground_homography),
                      ", ", Jsonb(tx, s.ranging_json), ", ", s.elapsed_ns, ")");
}

std::string BoardValues(const pqxx::work& tx, const std::string& station, int64_t cycle_id,
                        const std::string& sensor, const StoredBoardResult& b) {
  // Quoted through esc: GCC 12 inlines quote() here into a false -Wrestrict warning.
  const std::string residual = b.residual_rms ? Float(*b.residual_rms) : std::string("NULL");
  return absl::StrFormat("('%s', %d, '%s', '%s', %d, %d, %d, %s)", tx.esc(station), cycle_id,
                         tx.esc(sensor), tx.esc(b.board), b.frames, b.frames_found,
                         b.frames_partial, residual);
}

std::string EventValues(const pqxx::work& tx, const std::string& station, const StoredEvent& e,
                        int64_t cycle_id) {
  return absl::StrCat("(", tx.quote(station), ", ", cycle_id, ", ", e.sequence, ", ", e.time_ns,
                      ", ", tx.quote(std::string(EventTypeName(e.type))), ", ", tx.quote(e.sensor),
                      ", ", tx.quote(e.detail), ", ", tx.quote(VerdictName(e.verdict)), ")");
}

constexpr const char* kSensorColumns =
    "sensor, kind, verdict, reason, message, t_car_sensor, "
    "measured_yaw_deg, measured_pitch_deg, measured_roll_deg, measured_x_m, measured_y_m, "
    "measured_z_m, deviation_yaw_deg, deviation_pitch_deg, deviation_roll_deg, deviation_x_m, "
    "deviation_y_m, deviation_z_m, sigma_yaw_deg, sigma_pitch_deg, sigma_roll_deg, sigma_x_m, "
    "sigma_y_m, sigma_z_m, residual_rms, features_used, vanishing_point_u_px, "
    "vanishing_point_v_px, ground_homography, ranging, elapsed_ns";

// Reading back: the server prints float8 with the shortest text that round-trips
// (extra_float_digits 1, PostgreSQL ≥ 12), which SimpleAtod parses exactly.
double ParseFloat(const pqxx::field& f) {
  double v = 0;
  if (!f.is_null() && !absl::SimpleAtod(f.c_str(), &v)) v = std::nan("");
  return v;
}

std::vector<double> ParseFloatArray(const pqxx::field& f) {
  std::vector<double> values;
  if (f.is_null()) return values;
  const std::string text = absl::StrReplaceAll(f.c_str(), {{"{", ""}, {"}", ""}});
  for (absl::string_view part : absl::StrSplit(text, ',', absl::SkipEmpty())) {
    double v = 0;
    values.push_back(absl::SimpleAtod(part, &v) ? v : std::nan(""));
  }
  return values;
}

MountingValues ParseMounting(const pqxx::row& r, int first) {
  return {ParseFloat(r[first]),     ParseFloat(r[first + 1]), ParseFloat(r[first + 2]),
          ParseFloat(r[first + 3]), ParseFloat(r[first + 4]), ParseFloat(r[first + 5])};
}

std::string Text(const pqxx::field& f) { return f.is_null() ? "" : f.c_str(); }

// A refusal inside a transaction: Run ends it and returns the status.
struct Refusal {
  absl::Status status;
};

StoredSensorResult ParseSensor(const pqxx::row& r, int first) {
  StoredSensorResult s;
  s.sensor = Text(r[first]);
  const std::optional<SensorKind> kind = ParseSensorKind(Text(r[first + 1]));
  // Only forwarders write the column: another word is a damaged or foreign row.
  if (!kind) {
    throw Refusal{absl::DataLossError(absl::StrCat("sensor '", s.sensor, "' of unknown kind '",
                                                   Text(r[first + 1]), "' in the plant database"))};
  }
  s.kind = *kind;
  s.verdict = ParseVerdict(Text(r[first + 2]));
  s.reason = Text(r[first + 3]);
  s.message = Text(r[first + 4]);
  s.T_car_sensor = ParseFloatArray(r[first + 5]);
  s.measured = ParseMounting(r, first + 6);
  s.deviation = ParseMounting(r, first + 12);
  s.sigma = ParseMounting(r, first + 18);
  s.residual_rms = ParseFloat(r[first + 24]);
  s.features_used = r[first + 25].as<int>();
  if (!r[first + 26].is_null()) s.vanishing_point_u_px = ParseFloat(r[first + 26]);
  if (!r[first + 27].is_null()) s.vanishing_point_v_px = ParseFloat(r[first + 27]);
  s.ground_homography = ParseFloatArray(r[first + 28]);
  s.ranging_json = Text(r[first + 29]);
  s.elapsed_ns = r[first + 30].as<int64_t>();
  return s;
}

// The cycles a WHERE clause selects (over `cycles c`, parameters $1...), in `order`, with
// their sensors and boards: three statements in the caller's transaction.
template <typename... Args>
std::vector<PlantCycleRecord> ReadCycles(pqxx::work& tx, const std::string& where,
                                         const std::string& order, Args&&... args) {
  const pqxx::result cycles = tx.exec_params(
      absl::StrCat("SELECT station_id, cycle_id, vin, car_model, state, verdict, reason, "
                   "started_ns, ended_ns, request_json::text, capture_path, "
                   "(extract(epoch FROM received_at) * 1e9)::bigint FROM cycles c WHERE ",
                   where, " ORDER BY ", order),
      args...);
  std::vector<PlantCycleRecord> records;
  std::map<std::pair<std::string, int64_t>, size_t> index;
  for (const pqxx::row& r : cycles) {
    PlantCycleRecord record;
    record.station_id = Text(r[0]);
    StoredCycle& c = record.cycle;
    c.id = r[1].as<int64_t>();
    c.vin = Text(r[2]);
    c.car_model_id = Text(r[3]);
    c.state = ParseCycleState(Text(r[4]));
    c.verdict = ParseVerdict(Text(r[5]));
    c.reason = Text(r[6]);
    c.started_ns = r[7].as<int64_t>();
    c.ended_ns = r[8].as<int64_t>();
    c.request_json = Text(r[9]);
    c.capture_path = Text(r[10]);
    record.received_ns = r[11].as<int64_t>();
    index[{record.station_id, c.id}] = records.size();
    records.push_back(std::move(record));
  }
  if (records.empty()) return records;
  const pqxx::result sensors =
      tx.exec_params(absl::StrCat("SELECT s.station_id, s.cycle_id, ", kSensorColumns,
                                  " FROM sensor_results s WHERE (s.station_id, s.cycle_id) IN "
                                  "(SELECT c.station_id, c.cycle_id FROM cycles c WHERE ",
                                  where, ") ORDER BY s.station_id, s.cycle_id, s.sensor"),
                     args...);
  for (const pqxx::row& r : sensors) {
    auto it = index.find({Text(r[0]), r[1].as<int64_t>()});
    if (it != index.end()) records[it->second].cycle.sensors.push_back(ParseSensor(r, 2));
  }
  const pqxx::result boards = tx.exec_params(
      absl::StrCat("SELECT b.station_id, b.cycle_id, b.sensor, b.board, b.frames, "
                   "b.frames_found, b.frames_partial, b.residual_rms FROM board_results b "
                   "WHERE (b.station_id, b.cycle_id) IN (SELECT c.station_id, c.cycle_id FROM "
                   "cycles c WHERE ",
                   where, ") ORDER BY b.station_id, b.cycle_id, b.sensor, b.board"),
      args...);
  for (const pqxx::row& r : boards) {
    auto it = index.find({Text(r[0]), r[1].as<int64_t>()});
    if (it == index.end()) continue;
    for (StoredSensorResult& s : records[it->second].cycle.sensors) {
      if (s.sensor != Text(r[2])) continue;
      StoredBoardResult& b = s.boards.emplace_back();
      b.board = Text(r[3]);
      b.frames = r[4].as<int>();
      b.frames_found = r[5].as<int>();
      b.frames_partial = r[6].as<int>();
      if (!r[7].is_null()) b.residual_rms = ParseFloat(r[7]);
    }
  }
  return records;
}

// The first attempt of each VIN at each station started since $1, for station $2 and car
// model $3 ('' for every one): no earlier cycle id of that VIN at that station (ids only
// grow at a station, Store::BeginCycle).
constexpr const char* kFirstAttempts = R"sql(
WITH first AS (
  SELECT c.station_id, c.cycle_id, c.car_model, c.verdict FROM cycles c
  WHERE c.started_at >= to_timestamp($1::bigint / 1e9::float8) AND c.started_ns >= $1::bigint
    AND ($2 = '' OR c.station_id = $2) AND ($3 = '' OR c.car_model = $3)
    AND NOT EXISTS (SELECT FROM cycles p WHERE p.vin = c.vin
                    AND p.station_id = c.station_id AND p.cycle_id < c.cycle_id))
)sql";

// A refusal decided inside a transaction: Run rolls back and returns its status.
int ReadVersion(pqxx::work& tx) {
  const pqxx::row exists = tx.exec1("SELECT to_regclass('schema_migrations') IS NOT NULL");
  if (!exists[0].as<bool>()) return 0;
  return tx.exec1("SELECT coalesce(max(version), 0) FROM schema_migrations")[0].as<int>();
}

absl::Status NewerSchema(const std::string& server, int version) {
  return absl::FailedPreconditionError(absl::StrCat("plant database ", server, ": schema version ",
                                                    version, " is newer than this linecal's ",
                                                    PlantDb::kSchemaVersion, ": upgrade linecal"));
}

// Cuts a connection's socket when a call outlives its limit. statement_timeout is enforced
// by the server, and libpq waits for the server's answer without a limit of its own, so a
// server or network path that stops answering (a stalled proxy, a frozen host) would hang the
// caller forever; shutdown() wakes libpq with a lost connection instead. One thread per call:
// microseconds, against a round trip's fraction of a millisecond.
class Deadline {
 public:
  Deadline(int socket, std::chrono::milliseconds limit)
      : thread_([this, socket, limit] {
          std::unique_lock<std::mutex> lock(mutex_);
          if (!wake_.wait_for(lock, limit, [this] { return disarmed_; })) {
            ::shutdown(socket, SHUT_RDWR);
            fired_ = true;
          }
        }) {}
  ~Deadline() { Disarm(); }
  // Stops the clock; whether it had fired (the socket is then cut).
  bool Disarm() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      disarmed_ = true;
    }
    wake_.notify_one();
    if (thread_.joinable()) thread_.join();
    return fired_;
  }

 private:
  std::mutex mutex_;
  std::condition_variable wake_;
  bool disarmed_ = false;
  bool fired_ = false;
  std::thread thread_;  // last: starts once the members above exist
};

}  // namespace

PlantDb::PlantDb(std::string conninfo, std::string password, PlantDbOptions options,
                 std::string server)
    : conninfo_(std::move(conninfo)),
      password_(std::move(password)),
      options_(options),
      server_(std::move(server)) {}

PlantDb::~PlantDb() = default;

absl::StatusOr<std::unique_ptr<PlantDb>> PlantDb::Connect(const std::string& dsn,
                                                          const PlantDbOptions& options) {
  absl::StatusOr<ConnOptions> parsed = ParseDsn(dsn);
  if (!parsed.ok()) return parsed.status();
  const auto password = parsed->find("password");
  std::unique_ptr<PlantDb> db(new PlantDb(Conninfo(*parsed, options),
                                          password != parsed->end() ? password->second : "",
                                          options, ServerName(*parsed)));
  std::lock_guard<std::mutex> lock(db->mutex_);
  if (absl::Status s = db->EnsureConnected(); !s.ok()) return s;
  return db;
}

absl::Status PlantDb::EnsureConnected() {
  if (conn_ != nullptr) return absl::OkStatus();
  try {
    auto conn = std::make_unique<Connection>(conninfo_);
    conn->conn.set_variable("statement_timeout", absl::StrCat(options_.statement_timeout.count()));
    conn_ = std::move(conn);
    return absl::OkStatus();
  } catch (const pqxx::sql_error& e) {
    return SqlError(
        e, absl::StrCat("plant database ", server_, ": ", CleanMessage(e.what(), password_)));
  } catch (const std::exception& e) {
    return ConnectError(CleanMessage(e.what(), password_), server_);
  }
}

template <typename Body>
absl::Status PlantDb::Run(const Body& body) {
  if (absl::Status s = EnsureConnected(); !s.ok()) return s;
  auto failed = [&](const std::exception& e) {
    return absl::StrCat("plant database ", server_, ": ", CleanMessage(e.what(), password_));
  };
  auto attempt = [&]() -> absl::Status {
    try {
      pqxx::work tx(conn_->conn);
      body(tx);
      tx.commit();
      return absl::OkStatus();
    } catch (const Refusal& r) {
      return r.status;
    } catch (const pqxx::broken_connection& e) {
      return absl::UnavailableError(failed(e));
    } catch (const pqxx::in_doubt_error& e) {
      return absl::UnavailableError(failed(e));
    } catch (const pqxx::sql_error& e) {
      return SqlError(e, failed(e));
    } catch (const std::exception& e) {
      return absl::InternalError(failed(e));
    }
  };
  const std::chrono::milliseconds limit = 2 * options_.statement_timeout;
  absl::Status status;
  bool cut = false;
  {
    Deadline deadline(conn_->conn.sock(), limit);
    status = attempt();
    cut = deadline.Disarm();
  }
  // A lost, cut or unknown connection is not used again; the next call connects afresh.
  if (cut || absl::IsUnavailable(status) || absl::IsInternal(status)) conn_.reset();
  if (cut && !status.ok()) {
    return absl::UnavailableError(absl::StrCat("plant database ", server_, ": no answer within ",
                                               limit.count(),
                                               " ms (twice statement_timeout): "
                                               "connection dropped"));
  }
  return status;
}

absl::StatusOr<int> PlantDb::SchemaVersion() {
  std::lock_guard<std::mutex> lock(mutex_);
  int version = 0;
  absl::Status s = Run([&](pqxx::work& tx) { version = ReadVersion(tx); });
  if (!s.ok()) return s;
  return version;
}

absl::Status PlantDb::Migrate() {
  std::lock_guard<std::mutex> lock(mutex_);
  for (;;) {
    bool done = false;
    absl::Status s = Run([&](pqxx::work& tx) {
      tx.exec_params("SELECT pg_advisory_xact_lock($1)", kMigrationLockKey);
      tx.exec0(
          "CREATE TABLE IF NOT EXISTS schema_migrations ("
          "version integer PRIMARY KEY, applied_at timestamptz NOT NULL DEFAULT now())");
      const int version = ReadVersion(tx);
      if (version > kSchemaVersion) throw Refusal{NewerSchema(server_, version)};
      if (version == kSchemaVersion) {
        done = true;
        return;
      }
      tx.exec0(kMigrations[version]);
      tx.exec_params0("INSERT INTO schema_migrations (version) VALUES ($1)", version + 1);
    });
    if (!s.ok() || done) return s;
  }
}

absl::Status PlantDb::CheckSchema() {
  absl::StatusOr<int> version = SchemaVersion();
  if (!version.ok()) return version.status();
  if (*version > kSchemaVersion) return NewerSchema(server_, *version);
  if (*version < kSchemaVersion) {
    return absl::FailedPreconditionError(absl::StrCat(
        "plant database ", server_, ": schema version ", *version, " is older than this linecal's ",
        kSchemaVersion, ": run `linecal plant migrate`"));
  }
  return absl::OkStatus();
}

absl::Status PlantDb::ApplyBatch(const std::string& station_id,
                                 const std::vector<PlantCycle>& cycles) {
  if (station_id.empty()) return absl::InvalidArgumentError("ApplyBatch: empty station id");
  // The first copy of each cycle id counts; a later copy in the same batch is a duplicate.
  std::vector<const PlantCycle*> unique;
  std::set<int64_t> seen;
  for (const PlantCycle& p : cycles) {
    if (p.cycle.state == CycleState::kRunning) {
      return absl::InvalidArgumentError(absl::StrCat("ApplyBatch: station ", QuoteInput(station_id),
                                                     " cycle ", p.cycle.id, " is still running"));
    }
    if (seen.insert(p.cycle.id).second) unique.push_back(&p);
  }
  std::lock_guard<std::mutex> lock(mutex_);
  return Run([&](pqxx::work& tx) {
    tx.exec_params0("INSERT INTO stations (station_id) VALUES ($1) ON CONFLICT DO NOTHING",
                    station_id);
    if (unique.empty()) return;
    std::vector<std::string> rows;
    for (const PlantCycle* p : unique) rows.push_back(CycleValues(tx, station_id, p->cycle));
    const pqxx::result inserted = tx.exec(absl::StrCat(
        "INSERT INTO cycles (station_id, cycle_id, vin, car_model, state, verdict, reason, "
        "started_ns, ended_ns, capture_path, request_json) VALUES ",
        absl::StrJoin(rows, ", "), " ON CONFLICT DO NOTHING RETURNING cycle_id"));
    std::set<int64_t> fresh;
    for (const pqxx::row& r : inserted) fresh.insert(r[0].as<int64_t>());
    std::vector<std::string> sensors, boards, events;
    for (const PlantCycle* p : unique) {
      if (!fresh.count(p->cycle.id)) continue;  // present already: changes nothing
      for (const StoredSensorResult& s : p->cycle.sensors) {
        sensors.push_back(SensorValues(tx, station_id, p->cycle.id, s));
        for (const StoredBoardResult& b : s.boards) {
          boards.push_back(BoardValues(tx, station_id, p->cycle.id, s.sensor, b));
        }
      }
      for (const StoredEvent& e : p->events) {
        events.push_back(EventValues(tx, station_id, e, p->cycle.id));
      }
    }
    if (!sensors.empty()) {
      tx.exec0(absl::StrCat("INSERT INTO sensor_results (station_id, cycle_id, ", kSensorColumns,
                            ") VALUES ", absl::StrJoin(sensors, ", "), " ON CONFLICT DO NOTHING"));
    }
    if (!boards.empty()) {
      tx.exec0(
          absl::StrCat("INSERT INTO board_results (station_id, cycle_id, sensor, board, "
                       "frames, frames_found, frames_partial, residual_rms) VALUES ",
                       absl::StrJoin(boards, ", "), " ON CONFLICT DO NOTHING"));
    }
    if (!events.empty()) {
      tx.exec0(
          absl::StrCat("INSERT INTO events (station_id, cycle_id, sequence, time_ns, type, "
                       "sensor, detail, verdict) VALUES ",
                       absl::StrJoin(events, ", "), " ON CONFLICT DO NOTHING"));
    }
  });
}

absl::StatusOr<std::vector<PlantCycleRecord>> PlantDb::CyclesByVin(const std::string& vin) {
  std::lock_guard<std::mutex> lock(mutex_);
  std::vector<PlantCycleRecord> records;
  absl::Status s = Run([&](pqxx::work& tx) {
    records =
        ReadCycles(tx, "c.vin = $1", "c.started_ns DESC, c.station_id DESC, c.cycle_id DESC", vin);
  });
  if (!s.ok()) return s;
  return records;
}

absl::StatusOr<std::vector<PlantCycleRecord>> PlantDb::CyclesSince(int64_t since_ns, int limit) {
  if (limit < 1 || limit > 1000000) {
    return absl::InvalidArgumentError(absl::StrCat("limit ", limit, ": must be in [1, 1000000]"));
  }
  std::lock_guard<std::mutex> lock(mutex_);
  std::vector<PlantCycleRecord> records;
  absl::Status s = Run([&](pqxx::work& tx) {
    // The limit applies to cycles; the sensors' statement selects the same cycles.
    records = ReadCycles(tx,
                         "(c.station_id, c.cycle_id) IN (SELECT station_id, cycle_id FROM cycles "
                         "WHERE started_at >= to_timestamp($1::bigint / 1e9::float8) "
                         "AND started_ns >= $1::bigint "
                         "ORDER BY started_ns, station_id, cycle_id LIMIT $2)",
                         "c.started_ns, c.station_id, c.cycle_id", since_ns, limit);
  });
  if (!s.ok()) return s;
  return records;
}

absl::StatusOr<YieldReport> PlantDb::Yield(const YieldFilter& filter) {
  if (filter.top_reasons < 1 || filter.top_reasons > 100) {
    return absl::InvalidArgumentError(
        absl::StrCat("top reasons ", filter.top_reasons, ": must be in [1, 100]"));
  }
  std::lock_guard<std::mutex> lock(mutex_);
  YieldReport report;
  absl::Status s = Run([&](pqxx::work& tx) {
    const pqxx::result rows =
        tx.exec_params(absl::StrCat(kFirstAttempts, R"sql(
SELECT station_id, car_model, '' AS sensor, count(*), count(*) FILTER (WHERE verdict = 'pass')
  FROM first GROUP BY 1, 2
UNION ALL
SELECT f.station_id, f.car_model, s.sensor, count(*), count(*) FILTER (WHERE s.verdict = 'pass')
  FROM first f JOIN sensor_results s USING (station_id, cycle_id) GROUP BY 1, 2, 3
ORDER BY 1, 2, 3)sql"),
                       filter.since_ns, filter.station_id, filter.car_model_id);
    for (const pqxx::row& r : rows) {
      report.rows.push_back(
          {Text(r[0]), Text(r[1]), Text(r[2]), r[3].as<int64_t>(), r[4].as<int64_t>()});
    }
    const pqxx::result reasons =
        tx.exec_params(absl::StrCat(kFirstAttempts, R"sql(,
failed AS (
  SELECT s.sensor, s.reason, count(*) AS n FROM first f
    JOIN sensor_results s USING (station_id, cycle_id)
  WHERE s.verdict IN ('fail', 'error') GROUP BY 1, 2),
ranked AS (
  SELECT sensor, reason, n, row_number() OVER (PARTITION BY sensor ORDER BY n DESC, reason) AS k
  FROM failed)
SELECT sensor, reason, n FROM ranked WHERE k <= $4 ORDER BY sensor, n DESC, reason)sql"),
                       filter.since_ns, filter.station_id, filter.car_model_id, filter.top_reasons);
    for (const pqxx::row& r : reasons) {
      report.reasons.push_back({Text(r[0]), Text(r[1]), r[2].as<int64_t>()});
    }
  });
  if (!s.ok()) return s;
  return report;
}

}  // namespace linecal

#if defined(__SANITIZE_ADDRESS__)
// libpqxx 6.4 (Debian 12) leaks the PGresult of a statement whose connection broke while it
// ran: pqxx::connection_base::exec hands PQexec's result to make_result, which asks the
// broken connection for its encoding and throws before the result is owned (fixed upstream
// in 7.x, jtv/libpqxx pull request 500). About 2 kB per connection lost mid-statement, once
// per plant outage (docs/plant.md, "Known limits"); LeakSanitizer is told to leave that one
// library's leaks out, and still reports every leak of this project's code.
extern "C" const char* __lsan_default_suppressions() { return "leak:libpqxx-6.4.so\n"; }
#endif
