#pragma once
// The station's record of every car: cycles (every attempt), their per-sensor results and
// their progress events, in one SQLite file.
//
// Durability: WAL journal with synchronous=FULL, so a call that returned OK is on disk and
// survives a crash or power loss of the daemon; nothing committed is ever lost. A cycle found
// still `running` when the store opens was interrupted (crash, kill -9, power) and becomes
// `aborted` (reason "daemon_restarted", ended_ns the time it was found). The schema is
// versioned (PRAGMA user_version) and migrated forward on open; a file from a newer linecald
// is refused, never rewritten.
//
// Outbox (StoreOptions::outbox, docs/plant.md "Forwarding"): every cycle that ends — by
// EndCycle, or aborted at Open — is queued for the plant database in the same SQLite
// transaction that ends it, so a committed end is never missed and never queued twice. The
// forwarder reads the queue in order (ReadOutbox), ships it, then deletes what the plant
// acknowledged (MarkShipped): a crash between the two resends a batch, which the plant
// applies idempotently. Version 2 of the schema added the table; migrating from 1 queues
// nothing (cycles of a station that did not forward stay on the station). Version 3 added
// each sensor's per-board detections and residuals (StoredBoardResult); cycles stored before
// it have none.
//
// Errors (absl::Status, messages name the database file):
//   Unavailable         the database stayed locked by another process past the busy timeout
//   ResourceExhausted   the disk is full (SQLITE_FULL): nothing of the call was stored; the
//                       same call works again once space is freed
//   FailedPrecondition  a newer schema; ending a cycle that already ended; the database is
//                       in use by another Store (Open)
//   NotFound            unknown cycle id
//   InvalidArgument     a malformed page token or filter
//   Internal / DataLoss any other SQLite failure / a failed integrity check
// Thread safety: every method may be called from any thread (one connection, one mutex).

#include <sys/types.h>

#include <chrono>
#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "station/model/car_model.h"
#include "station/model/verdict.h"

struct sqlite3;

namespace linecal {

enum class CycleState { kRunning, kDone, kCancelled, kAborted };

// A value from a request as an error message quotes it: 'value' when it has at most
// kMaxQuotedBytes bytes, else its first kMaxQuotedBytes bytes, "…" and its size
// ('AAAA…' (10240 bytes)). A message that echoed a 3 MB field would be 3 MB, and gRPC
// refuses a status over its metadata limit (8 kB by default), so the client would see
// RESOURCE_EXHAUSTED instead of the refusal. Pure; O(kMaxQuotedBytes). 64 bytes: enough to
// recognise a value (a VIN, an id, a token), under 1% of that limit.
inline constexpr size_t kMaxQuotedBytes = 64;
std::string QuoteInput(absl::string_view value);

// "running", "done", "cancelled", "aborted" — the words stored in the database.
const char* CycleStateName(CycleState state);
// A stored verdict's word: VerdictName's (station/model/verdict.h), "" for none (a running
// cycle, an event without one) — the words of docs/interfaces.md's results. The inverse is
// ParseVerdict, nullopt for "".
const char* VerdictName(std::optional<Verdict> verdict);
// The inverse of CycleStateName; an unknown word gives kRunning.
CycleState ParseCycleState(const std::string& name);

// What happened in a cycle (docs/interfaces.md), in the order a cycle has them.
enum class EventType {
  kStarted,
  kSensorAcquired,
  kSensorProgress,
  kBoardFound,
  kSensorSolved,
  kSensorError,
  kSensorVerdict,
  kCycleEnded,
};
// "started", "sensor_acquired", "sensor_progress", "board_found", "sensor_solved",
// "sensor_error", "sensor_verdict", "cycle_ended": the words stored in the database and
// shown by the console. Pure.
const char* EventTypeName(EventType type);
// The inverse of EventTypeName; nullopt for any other word. Pure.
std::optional<EventType> ParseEventType(absl::string_view name);

// Yaw/pitch/roll (degrees, docs/conventions.md) and position (metres) of a sensor in the car.
struct MountingValues {
  double yaw_deg = 0, pitch_deg = 0, roll_deg = 0;
  double x_m = 0, y_m = 0, z_m = 0;
  bool operator==(const MountingValues&) const = default;
};

// One target board as one sensor saw it in a cycle (cameras and LiDARs; schema version 3):
// the detections of SensorCalibration::boards and, when the sensor was solved with the board,
// its own residual (BoardResidual).
struct StoredBoardResult {
  std::string board;
  int frames = 0;                      // frames (LiDARs: accumulated scans) it was looked for in
  int frames_found = 0;                // of those, frames with the whole board
  int frames_partial = 0;              // frames with certain features of a partly seen board
  std::optional<double> residual_rms;  // the sensor's unit; none when it did not enter a solve
  bool operator==(const StoredBoardResult&) const = default;
};

struct StoredSensorResult {
  std::string sensor;                     // the car model's sensor name
  SensorKind kind = SensorKind::kCamera;  // stored as SensorKindName's word
  std::optional<Verdict> verdict;
  std::string reason;                // a code ("yaw_out_of_tolerance"); empty on pass
  std::string message;               // the same for a person
  std::vector<double> T_car_sensor;  // 16 values, row-major; empty when not solved
  MountingValues measured, deviation, sigma;
  double residual_rms = 0;  // pixels (cameras), metres (LiDARs), degrees (radars)
  int features_used = 0;
  std::optional<double> vanishing_point_u_px, vanishing_point_v_px;  // cameras
  std::vector<double> ground_homography;  // cameras: 9 values, row-major; else empty
  std::string ranging_json;               // cameras: the ranging check as JSON; else empty
  int64_t elapsed_ns = 0;                 // acquire to verdict
  std::vector<StoredBoardResult> boards;  // by board id; empty for radars and older cycles
  bool operator==(const StoredSensorResult&) const = default;
};

struct StoredCycle {
  int64_t id = 0;  // assigned by BeginCycle: increasing, never reused
  std::string vin;
  std::string car_model_id;
  CycleState state = CycleState::kRunning;
  std::optional<Verdict> verdict;  // none while running
  std::string reason;
  int64_t started_ns = 0;                   // Unix epoch
  int64_t ended_ns = 0;                     // 0 while running
  std::string request_json;                 // the request as received (VIN, aligner, options)
  std::string capture_path;                 // relative to the data root, when recorded
  std::vector<StoredSensorResult> sensors;  // by sensor name; filled by GetCycle only
};

struct StoredEvent {
  int64_t cycle_id = 0;
  int64_t sequence = 0;  // 0, 1, 2, ... per cycle, assigned by AppendEvent
  int64_t time_ns = 0;
  EventType type = EventType::kStarted;
  std::string sensor;  // empty for cycle-wide events
  std::string detail;
  std::optional<Verdict> verdict;  // sensor_verdict, sensor_error and cycle_ended have one
};

struct CycleFilter {
  std::string vin;                 // empty: every VIN
  int64_t since_ns = 0;            // started at or after; 0: no bound
  int64_t until_ns = 0;            // started before; 0: no bound
  std::optional<Verdict> verdict;  // nullopt: every verdict
  int page_size = 50;              // 1..1000
  std::string page_token;          // empty: the first page
};

struct CyclePage {
  std::vector<StoredCycle> cycles;  // newest first, without sensors
  std::string next_page_token;      // empty on the last page
};

// A solved sensor result of a done cycle, as trends read it (Store::RecentSolvedResults).
struct TrendRow {
  int64_t cycle_id = 0;
  int64_t started_ns = 0;
  std::string car_model_id;
  std::string sensor;
  MountingValues deviation;
  double residual_rms = 0;
};

// A target board of a sensor in a done cycle, as trends read it (Store::RecentBoardResults).
struct BoardTrendRow {
  int64_t cycle_id = 0;
  int64_t started_ns = 0;
  std::string car_model_id;
  std::string sensor;
  bool solved = false;  // the sensor's mounting was found
  StoredBoardResult board;
};

struct StoreOptions {
  // How long a call waits for another process's lock before giving up with Unavailable.
  // 5 s: longer than any write of ours takes, short enough for a cycle to end in error
  // rather than hang the line.
  std::chrono::milliseconds busy_timeout{5000};
  // Queue every ended cycle in the outbox (a `plant` section is configured). False: nothing
  // is queued, so a station that does not forward never grows the table.
  bool outbox = false;
};

// One queued cycle of the outbox: its place in the queue, the cycle with its sensors, and
// its events in sequence order (the shape of daemon/plant/plant_cycle.h's PlantCycle).
struct OutboxEntry {
  int64_t seq = 0;  // increasing in queue order, never reused
  StoredCycle cycle;
  std::vector<StoredEvent> events;
};

struct OutboxBacklog {
  int64_t cycles = 0;           // queued, not yet shipped
  int64_t oldest_ended_ns = 0;  // the first queued cycle's end (Unix epoch); 0 when empty
};

class Store {
 public:
  // The current schema version (PRAGMA user_version after Open).
  static constexpr int kSchemaVersion = 3;

  // Opens or creates the database at `path` (its directory must exist), migrates it to
  // kSchemaVersion and turns running cycles into aborted ones. Cost: a few fsyncs.
  // One Store per database: before SQLite opens the file, Open takes an exclusive flock on
  // `<path>.lock` (created if needed; the holder's pid written into it) and holds it until
  // the Store is destroyed (the kernel drops it when the process dies, kill -9 too). While
  // another Store, in this process or another, holds it, Open fails FailedPrecondition
  // naming the lock file and the holder's pid, and has written nothing: a second daemon on
  // the same database would otherwise abort the first one's running cycle.
  static absl::StatusOr<std::unique_ptr<Store>> Open(const std::string& path,
                                                     const StoreOptions& options = {});
  ~Store();
  Store(const Store&) = delete;
  Store& operator=(const Store&) = delete;

  const std::string& path() const { return path_; }
  // Cycles that Open found running and stored as aborted: their number, and the cycles as
  // they were stored before (state running, ended_ns 0; without sensors), oldest first, for
  // whoever must clean up after them (their partial captures: StationCore::Create).
  int aborted_at_open() const { return static_cast<int>(aborted_at_open_.size()); }
  const std::vector<StoredCycle>& aborted_cycles_at_open() const { return aborted_at_open_; }

  // Stores a new running cycle (`cycle.id`, state, verdict and sensors are ignored) and
  // its car; returns the cycle's id.
  absl::StatusOr<int64_t> BeginCycle(const StoredCycle& cycle);
  // Appends an event to a cycle; returns its sequence number. NotFound for an unknown cycle.
  absl::StatusOr<int64_t> AppendEvent(const StoredEvent& event);
  // Stores (or replaces) the result of one sensor of a running cycle.
  absl::Status PutSensorResult(int64_t cycle_id, const StoredSensorResult& result);
  // Ends a running cycle: state (not kRunning), overall verdict and reason, end time.
  // FailedPrecondition when it already ended.
  absl::Status EndCycle(int64_t cycle_id, CycleState state, Verdict verdict,
                        const std::string& reason, int64_t ended_ns);

  absl::StatusOr<StoredCycle> GetCycle(int64_t cycle_id);
  absl::StatusOr<std::vector<StoredEvent>> Events(int64_t cycle_id);
  absl::StatusOr<CyclePage> ListCycles(const CycleFilter& filter);
  // The newest running cycle's id, if any.
  absl::StatusOr<std::optional<int64_t>> RunningCycle();
  // The solved results (a mounting stored) of the newest `cycles` (1..100000) cycles that
  // ended done, oldest cycle first, by sensor name within a cycle. InvalidArgument for a count
  // out of range. One query; cost O(cycles × sensors) (10,000 cycles of 10 sensors: ~0.1 s).
  absl::StatusOr<std::vector<TrendRow>> RecentSolvedResults(int cycles);
  // Every stored board result (solved sensor or not) of the same newest `cycles` cycles that
  // ended done, oldest cycle first, by sensor and board within a cycle. InvalidArgument for a
  // count out of range. One query; cost O(cycles × sensors × boards of a sensor).
  absl::StatusOr<std::vector<BoardTrendRow>> RecentBoardResults(int cycles);

  // The first `limit` (>= 1) queued cycles in queue order, each with its sensors and events,
  // read in one transaction. Cost: three queries per cycle.
  absl::StatusOr<std::vector<OutboxEntry>> ReadOutbox(int limit);
  // Removes the queued cycles up to and including `seq` (they reached the plant). Cost: one
  // fsynced commit.
  absl::Status MarkShipped(int64_t seq);
  // How many cycles are queued and when the first of them ended. Cost: one query, O(queued).
  absl::StatusOr<OutboxBacklog> Backlog();

  // PRAGMA integrity_check: OK, or DataLoss with SQLite's first complaint.
  absl::Status IntegrityCheck();

  // Whether path() still names the file that Open opened: a database file deleted (or its
  // folder) while the Store is open is still written by SQLite through its open descriptor,
  // every call succeeding, and all of it is lost when the process ends. FailedPrecondition
  // naming the file when it is gone or another file took its place. Cost: one stat.
  absl::Status CheckFile() const;

 private:
  Store(sqlite3* db, std::string path, int lock_fd, bool outbox)
      : db_(db), path_(std::move(path)), lock_fd_(lock_fd), outbox_(outbox) {}
  absl::Status Migrate();
  absl::Status AbortRunning();
  // Queues `cycle_id` in the outbox when it is kept; inside the caller's transaction.
  absl::Status Enqueue(int64_t cycle_id);
  // Inserts the board results of `r` in cycle_id (the old ones deleted); inside the caller's
  // transaction.
  absl::Status PutBoardResultsLocked(int64_t cycle_id, const StoredSensorResult& r);
  // GetCycle and Events without taking mutex_ (the caller holds it).
  absl::StatusOr<StoredCycle> ReadCycleLocked(int64_t cycle_id);
  absl::StatusOr<std::vector<StoredEvent>> ReadEventsLocked(int64_t cycle_id);
  absl::StatusOr<std::vector<OutboxEntry>> ReadOutboxLocked(int limit);

  std::mutex mutex_;
  sqlite3* db_;
  std::string path_;
  int lock_fd_;        // holds the flock on <path>.lock
  const bool outbox_;  // StoreOptions::outbox
  // The identity (st_dev, st_ino) of the database file when it was opened.
  dev_t file_dev_ = 0;
  ino_t file_ino_ = 0;
  std::vector<StoredCycle> aborted_at_open_;
};

}  // namespace linecal
