#pragma once
// The plant PostgreSQL database (docs/plant.md): every station's ended cycles, their
// per-sensor results and events in one place, for tracing a VIN across stations and days and
// for first-pass yield. Stations write through ApplyBatch (the forwarder,
// daemon/plant/forwarder.h); `linecal plant ...` migrates the schema and runs the queries.
//
// Errors (absl::Status; messages name the server as host:port and never hold the password):
//   Unavailable         the server is down, refuses connections, timed out, dropped the
//                       connection, cancelled a statement past statement_timeout or did not
//                       answer within twice that; or a transaction conflicted. Retryable: nothing
//                       of the call was committed, except that a batch whose COMMIT was sent when
//                       the connection dropped may be committed; applying it again changes nothing.
//   PermissionDenied    authentication failed, or the role lacks a privilege the call needs
//   InvalidArgument     a malformed connection string, or a query's bad argument
//   NotFound            the database named by the connection string does not exist
//   FailedPrecondition  the schema is older or newer than kSchemaVersion (both named);
//                       Migrate: the schema is newer than this linecal
//   Internal            any other server error (SQLSTATE in the message)
// After Unavailable the next call reconnects (one attempt, bounded by connect_timeout).
// Thread safety: every method may be called from any thread (one connection, one mutex).
// Cost: one connection; ApplyBatch is a handful of round trips per batch, not per row; a
// watchdog thread per call (the statement_timeout limit below).

#include <chrono>
#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "daemon/plant/plant_cycle.h"

namespace linecal {

struct PlantDbOptions {
  // libpq's connect_timeout (whole seconds, at least 2: libpq's own floor), so a server
  // that swallows packets fails a call instead of hanging the forwarder.
  std::chrono::milliseconds connect_timeout{5000};
  // statement_timeout of every session: a slow statement is cancelled by the server
  // (Unavailable). A call that has no answer at all after twice this (a stalled server or
  // network path) has its connection cut by the client (Unavailable).
  std::chrono::milliseconds statement_timeout{10000};
};

// One attempt at one station, as the plant holds it.
struct PlantCycleRecord {
  std::string station_id;
  StoredCycle cycle;        // with its sensors, by sensor name
  int64_t received_ns = 0;  // when the plant database stored it (Unix epoch)
};

struct YieldFilter {
  int64_t since_ns = 0;      // first attempts started at or after this time (Unix epoch)
  std::string station_id;    // empty: every station
  std::string car_model_id;  // empty: every car model
  int top_reasons = 3;       // failure reasons kept per sensor, 1..100
};

// First-pass yield of one station, car model and sensor: among the cars whose first attempt
// at that station started since the filter's time, how many passed on it.
struct YieldRow {
  std::string station_id;
  std::string car_model_id;
  std::string sensor;  // empty: the whole cycle (its overall verdict)
  int64_t first_attempts = 0;
  int64_t passed = 0;
};

// How often a sensor failed (verdict fail or error) with a reason on first attempts.
struct FailureReason {
  std::string sensor;
  std::string reason;
  int64_t count = 0;
};

struct YieldReport {
  std::vector<YieldRow> rows;          // by station, car model, sensor ("" first)
  std::vector<FailureReason> reasons;  // by sensor, then count (highest first), reason
};

class PlantDb {
 public:
  static constexpr int kSchemaVersion = 2;

  // Connects with `dsn`, a libpq connection string ("host=... port=... dbname=... user=...",
  // or a postgresql:// URI); the password comes from it, PGPASSWORD or ~/.pgpass. Does not
  // check the schema (CheckSchema does). Errors: see above.
  static absl::StatusOr<std::unique_ptr<PlantDb>> Connect(const std::string& dsn,
                                                          const PlantDbOptions& options = {});
  ~PlantDb();
  PlantDb(const PlantDb&) = delete;
  PlantDb& operator=(const PlantDb&) = delete;

  // "host:port" (or the socket directory and port) of the server, for messages.
  const std::string& server() const { return server_; }

  // The schema's version: 0 for an empty database.
  absl::StatusOr<int> SchemaVersion();
  // Applies the missing migrations, each in its own transaction, and records them in
  // schema_migrations; a no-op when up to date. Needs a role that may create tables and
  // roles (the DBA's). FailedPrecondition, changing nothing, for a newer schema.
  absl::Status Migrate();
  // OK when the schema is exactly kSchemaVersion, else FailedPrecondition naming both.
  absl::Status CheckSchema();

  // Stores ended cycles of one station in one transaction. Idempotent: a cycle whose
  // (station_id, cycle.id) is present already changes nothing (nor do its sensors and
  // events), so at-least-once delivery gives exactly one row per cycle; cycles may come in
  // any order and with gaps. Registers the station on first sight. An empty batch only
  // registers the station. InvalidArgument (nothing stored) for an empty station id or a
  // cycle still running. Needs the linecal_station role (or more).
  absl::Status ApplyBatch(const std::string& station_id, const std::vector<PlantCycle>& cycles);

  // Reports (the linecal_report role suffices):
  // Every attempt at every station on this VIN, newest first (started, then station id and
  // cycle id, descending), with sensors.
  absl::StatusOr<std::vector<PlantCycleRecord>> CyclesByVin(const std::string& vin);
  // First-pass yield: the first attempt of each VIN at each station counts (retries do not).
  // InvalidArgument for top_reasons outside 1..100.
  absl::StatusOr<YieldReport> Yield(const YieldFilter& filter);
  // Cycles started at or after since_ns, oldest first (started, station id, cycle id), with
  // sensors; at most `limit` of them (1..1,000,000): InvalidArgument outside.
  absl::StatusOr<std::vector<PlantCycleRecord>> CyclesSince(int64_t since_ns, int limit);

 private:
  PlantDb(std::string conninfo, std::string password, PlantDbOptions options, std::string server);
  // Connects when not connected (mutex_ held).
  absl::Status EnsureConnected();
  // Runs `body(pqxx::work&)` in a transaction and commits; maps failures to the statuses
  // above and drops a lost connection (mutex_ held). Defined and used in plant_db.cc only.
  template <typename Body>
  absl::Status Run(const Body& body);

  std::mutex mutex_;
  const std::string conninfo_;  // holds the password when the DSN does: never printed
  const std::string password_;  // masked in messages, should a server ever echo it
  const PlantDbOptions options_;
  const std::string server_;
  struct Connection;                  // the libpqxx connection (plant_db.cc)
  std::unique_ptr<Connection> conn_;  // null after a lost connection
};

}  // namespace linecal
