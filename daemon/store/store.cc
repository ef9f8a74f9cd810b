#include "daemon/store/store.h"

#include <fcntl.h>
#include <sqlite3.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <utility>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "absl/strings/str_split.h"

namespace linecal {
namespace {

// Schema migrations: kMigrations[i] takes the database from version i to i + 1. Append new
// versions; never edit a released one (old files must keep migrating the same way).
constexpr const char* kMigrations[] = {
    R"sql(
CREATE TABLE cars (
  vin TEXT PRIMARY KEY,
  car_model_id TEXT NOT NULL,
  first_seen_ns INTEGER NOT NULL,
  last_cycle_id INTEGER
);
CREATE TABLE cycles (
  id INTEGER PRIMARY KEY AUTOINCREMENT,
  vin TEXT NOT NULL REFERENCES cars(vin),
  car_model_id TEXT NOT NULL,
  state TEXT NOT NULL CHECK (state IN ('running', 'done', 'cancelled', 'aborted')),
  verdict TEXT NOT NULL CHECK (verdict IN ('', 'pass', 'fail', 'error')),
  reason TEXT NOT NULL DEFAULT '',
  started_ns INTEGER NOT NULL,
  ended_ns INTEGER NOT NULL DEFAULT 0,
  request_json TEXT NOT NULL,
  capture_path TEXT NOT NULL DEFAULT ''
);
CREATE INDEX cycles_by_vin ON cycles (vin, started_ns);
CREATE INDEX cycles_by_start ON cycles (started_ns, id);
CREATE INDEX cycles_running ON cycles (state) WHERE state = 'running';
CREATE TABLE sensor_results (
  cycle_id INTEGER NOT NULL REFERENCES cycles(id),
  sensor TEXT NOT NULL,
  kind TEXT NOT NULL,
  verdict TEXT NOT NULL CHECK (verdict IN ('', 'pass', 'fail', 'error')),
  reason TEXT NOT NULL,
  message TEXT NOT NULL,
  T_car_sensor TEXT NOT NULL,
  yaw_deg REAL, pitch_deg REAL, roll_deg REAL, x_m REAL, y_m REAL, z_m REAL,
  d_yaw_deg REAL, d_pitch_deg REAL, d_roll_deg REAL, d_x_m REAL, d_y_m REAL, d_z_m REAL,
  s_yaw_deg REAL, s_pitch_deg REAL, s_roll_deg REAL, s_x_m REAL, s_y_m REAL, s_z_m REAL,
  residual_rms REAL NOT NULL,
  features_used INTEGER NOT NULL,
  vanishing_point_u_px REAL,
  vanishing_point_v_px REAL,
  ground_homography TEXT NOT NULL,
  ranging_json TEXT NOT NULL,
  elapsed_ns INTEGER NOT NULL,
  PRIMARY KEY (cycle_id, sensor)
);
CREATE TABLE events (
  cycle_id INTEGER NOT NULL REFERENCES cycles(id),
  sequence INTEGER NOT NULL,
  time_ns INTEGER NOT NULL,
  type TEXT NOT NULL,
  sensor TEXT NOT NULL,
  detail TEXT NOT NULL,
  verdict TEXT NOT NULL,
  PRIMARY KEY (cycle_id, sequence)
);
)sql",
    // 2: the outbox of cycles to forward to the plant database, in queue order. AUTOINCREMENT:
    // a sequence number is never reused, even once the queue was emptied.
    R"sql(
CREATE TABLE outbox (
  seq INTEGER PRIMARY KEY AUTOINCREMENT,
  cycle_id INTEGER NOT NULL UNIQUE REFERENCES cycles(id)
);
)sql",
    // 3: each sensor's target boards in a cycle: detections and the board's own residual
    // (NULL when it did not enter a solve), for the moved-target alarm and detection counts.
    R"sql(
CREATE TABLE board_results (
  cycle_id INTEGER NOT NULL,
  sensor TEXT NOT NULL,
  board TEXT NOT NULL,
  frames INTEGER NOT NULL,
  frames_found INTEGER NOT NULL,
  frames_partial INTEGER NOT NULL,
  residual_rms REAL,
  PRIMARY KEY (cycle_id, sensor, board),
  FOREIGN KEY (cycle_id, sensor) REFERENCES sensor_results (cycle_id, sensor)
);
)sql",
};
constexpr int kMigrationCount = sizeof(kMigrations) / sizeof(kMigrations[0]);
static_assert(kMigrationCount == Store::kSchemaVersion);

// One prepared statement, finalised on scope exit. Binds are 1-based like SQLite's.
class Statement {
 public:
  Statement(sqlite3* db, const char* sql) {
    rc_ = sqlite3_prepare_v2(db, sql, -1, &stmt_, nullptr);
  }
  ~Statement() { sqlite3_finalize(stmt_); }
  Statement(const Statement&) = delete;
  Statement& operator=(const Statement&) = delete;

  bool ok() const { return rc_ == SQLITE_OK; }
  Statement& Bind(int i, int64_t v) {
    Keep(sqlite3_bind_int64(stmt_, i, v));
    return *this;
  }
  Statement& Bind(int i, double v) {
    Keep(sqlite3_bind_double(stmt_, i, v));
    return *this;
  }
  Statement& Bind(int i, const std::string& v) {
    Keep(sqlite3_bind_text(stmt_, i, v.data(), static_cast<int>(v.size()), SQLITE_TRANSIENT));
    return *this;
  }
  Statement& Bind(int i, const std::optional<double>& v) {
    Keep(v ? sqlite3_bind_double(stmt_, i, *v) : sqlite3_bind_null(stmt_, i));
    return *this;
  }
  // SQLITE_ROW, SQLITE_DONE, or the first error of prepare, bind or step.
  int Step() {
    if (rc_ != SQLITE_OK && rc_ != SQLITE_ROW && rc_ != SQLITE_DONE) return rc_;
    rc_ = sqlite3_step(stmt_);
    return rc_;
  }
  int64_t Int(int col) const { return sqlite3_column_int64(stmt_, col); }
  double Real(int col) const { return sqlite3_column_double(stmt_, col); }
  bool IsNull(int col) const { return sqlite3_column_type(stmt_, col) == SQLITE_NULL; }
  std::string Text(int col) const {
    const unsigned char* p = sqlite3_column_text(stmt_, col);
    return p ? std::string(reinterpret_cast<const char*>(p), sqlite3_column_bytes(stmt_, col)) : "";
  }

 private:
  void Keep(int rc) {
    if (rc_ == SQLITE_OK && rc != SQLITE_OK) rc_ = rc;
  }
  sqlite3_stmt* stmt_ = nullptr;
  int rc_;
};

absl::Status SqliteError(sqlite3* db, const std::string& path, const char* what, int rc) {
  const std::string message = absl::StrCat(
      "database ", path, ": ", what, ": ", sqlite3_errstr(rc),
      db && sqlite3_errcode(db) == rc ? absl::StrCat(" (", sqlite3_errmsg(db), ")") : "");
  if (rc == SQLITE_BUSY || rc == SQLITE_LOCKED) return absl::UnavailableError(message);
  // SQLITE_FULL: the file system has no room (or the file hit its size limit); the write
  // works again once space is freed, so the caller may keep what it meant to store.
  if (rc == SQLITE_FULL) return absl::ResourceExhaustedError(message);
  if (rc == SQLITE_CORRUPT || rc == SQLITE_NOTADB) return absl::DataLossError(message);
  return absl::InternalError(message);
}

absl::Status Exec(sqlite3* db, const std::string& path, const char* what, const char* sql) {
  const int rc = sqlite3_exec(db, sql, nullptr, nullptr, nullptr);
  return rc == SQLITE_OK ? absl::OkStatus() : SqliteError(db, path, what, rc);
}

// BEGIN IMMEDIATE ... COMMIT, rolled back unless Commit() succeeded. IMMEDIATE takes the
// write lock up front, so a busy database fails at the start instead of halfway.
class Transaction {
 public:
  Transaction(sqlite3* db, const std::string& path) : db_(db), path_(path) {
    status_ = Exec(db, path, "begin", "BEGIN IMMEDIATE");
  }
  ~Transaction() {
    if (status_.ok() && !committed_) sqlite3_exec(db_, "ROLLBACK", nullptr, nullptr, nullptr);
  }
  const absl::Status& status() const { return status_; }
  absl::Status Commit() {
    absl::Status s = Exec(db_, path_, "commit", "COMMIT");
    committed_ = s.ok();
    return s;
  }

 private:
  sqlite3* db_;
  const std::string& path_;
  absl::Status status_;
  bool committed_ = false;
};

std::string Numbers(const std::vector<double>& values) {
  return absl::StrJoin(values, " ", [](std::string* out, double v) {
    absl::StrAppend(out, absl::StrFormat("%.17g", v));
  });
}

std::vector<double> ParseNumbers(const std::string& text) {
  std::vector<double> values;
  for (absl::string_view part : absl::StrSplit(text, ' ', absl::SkipEmpty())) {
    double v = 0;
    if (absl::SimpleAtod(part, &v)) values.push_back(v);
  }
  return values;
}

constexpr const char* kCycleColumns =
    "id, vin, car_model_id, state, verdict, reason, started_ns, ended_ns, request_json, "
    "capture_path";

StoredCycle ReadCycle(const Statement& s) {
  StoredCycle c;
  c.id = s.Int(0);
  c.vin = s.Text(1);
  c.car_model_id = s.Text(2);
  c.state = ParseCycleState(s.Text(3));
  c.verdict = ParseVerdict(s.Text(4));
  c.reason = s.Text(5);
  c.started_ns = s.Int(6);
  c.ended_ns = s.Int(7);
  c.request_json = s.Text(8);
  c.capture_path = s.Text(9);
  return c;
}

// A board_results row's board, from column `first` (board, frames, frames_found,
// frames_partial, residual_rms).
StoredBoardResult ReadBoard(const Statement& s, int first) {
  StoredBoardResult b;
  b.board = s.Text(first);
  b.frames = static_cast<int>(s.Int(first + 1));
  b.frames_found = static_cast<int>(s.Int(first + 2));
  b.frames_partial = static_cast<int>(s.Int(first + 3));
  if (!s.IsNull(first + 4)) b.residual_rms = s.Real(first + 4);
  return b;
}

// The pid a lock file's holder wrote into it, for the message of the one refused.
std::string LockHolder(int fd) {
  char buffer[32] = {};  // a pid and a newline: at most 8 bytes on Linux (pid_max 4194304)
  const ssize_t n = ::pread(fd, buffer, sizeof buffer - 1, 0);
  int64_t pid = 0;
  if (n <= 0 || !absl::SimpleAtoi(absl::string_view(buffer, static_cast<size_t>(n)), &pid)) {
    return "unknown";
  }
  return absl::StrCat(pid);
}

// Takes the exclusive flock on `<db_path>.lock` (Store::Open's contract); returns its
// descriptor, which holds the lock until closed.
absl::StatusOr<int> LockDatabase(const std::string& db_path) {
  const std::string lock_path = db_path + ".lock";
  const int fd = ::open(lock_path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  if (fd < 0) {
    return absl::InternalError(absl::StrCat("database ", db_path, ": cannot open the lock file ",
                                            lock_path, ": ", std::strerror(errno)));
  }
  if (::flock(fd, LOCK_EX | LOCK_NB) != 0) {
    const int error = errno;
    const std::string holder = LockHolder(fd);
    ::close(fd);
    if (error == EWOULDBLOCK) {
      return absl::FailedPreconditionError(
          absl::StrCat("database ", db_path, ": in use by another linecald (pid ", holder,
                       " holds the lock file ", lock_path, ")"));
    }
    return absl::InternalError(absl::StrCat("database ", db_path, ": cannot lock ", lock_path, ": ",
                                            std::strerror(error)));
  }
  const std::string pid = absl::StrCat(::getpid(), "\n");
  // The pid is for messages only: a lock file that cannot be rewritten still locks.
  if (::ftruncate(fd, 0) == 0) (void)!::pwrite(fd, pid.data(), pid.size(), 0);
  return fd;
}

}  // namespace

std::string QuoteInput(absl::string_view value) {
  if (value.size() <= kMaxQuotedBytes) return absl::StrCat("'", value, "'");
  // Cut before a UTF-8 continuation byte, not inside a character.
  size_t cut = kMaxQuotedBytes;
  while (cut > 0 && (static_cast<unsigned char>(value[cut]) & 0xC0) == 0x80) --cut;
  return absl::StrCat("'", value.substr(0, cut), "…' (", value.size(), " bytes)");
}

const char* CycleStateName(CycleState state) {
  switch (state) {
    case CycleState::kRunning:
      return "running";
    case CycleState::kDone:
      return "done";
    case CycleState::kCancelled:
      return "cancelled";
    case CycleState::kAborted:
      return "aborted";
  }
  return "running";
}

const char* VerdictName(std::optional<Verdict> verdict) {
  return verdict ? VerdictName(*verdict) : "";
}

const char* EventTypeName(EventType type) {
  switch (type) {
    case EventType::kStarted:
      return "started";
    case EventType::kSensorAcquired:
      return "sensor_acquired";
    case EventType::kSensorProgress:
      return "sensor_progress";
    case EventType::kBoardFound:
      return "board_found";
    case EventType::kSensorSolved:
      return "sensor_solved";
    case EventType::kSensorError:
      return "sensor_error";
    case EventType::kSensorVerdict:
      return "sensor_verdict";
    case EventType::kCycleEnded:
      return "cycle_ended";
  }
  return "started";
}

std::optional<EventType> ParseEventType(absl::string_view name) {
  for (int i = 0; i <= static_cast<int>(EventType::kCycleEnded); ++i) {
    if (name == EventTypeName(static_cast<EventType>(i))) return static_cast<EventType>(i);
  }
  return std::nullopt;
}

CycleState ParseCycleState(const std::string& s) {
  if (s == "done") return CycleState::kDone;
  if (s == "cancelled") return CycleState::kCancelled;
  if (s == "aborted") return CycleState::kAborted;
  return CycleState::kRunning;
}

absl::StatusOr<std::unique_ptr<Store>> Store::Open(const std::string& path,
                                                   const StoreOptions& options) {
  absl::StatusOr<int> lock_fd = LockDatabase(path);
  if (!lock_fd.ok()) return lock_fd.status();
  sqlite3* db = nullptr;
  const int rc =
      sqlite3_open_v2(path.c_str(), &db,
                      SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE | SQLITE_OPEN_FULLMUTEX, nullptr);
  if (rc != SQLITE_OK) {
    absl::Status s = SqliteError(db, path, "open", rc);
    sqlite3_close(db);
    ::close(*lock_fd);
    return s;
  }
  std::unique_ptr<Store> store(new Store(db, path, *lock_fd, options.outbox));
  // The file SQLite opened, by identity: CheckFile compares the path's file with it.
  struct stat opened {};
  if (::stat(path.c_str(), &opened) == 0) {
    store->file_dev_ = opened.st_dev;
    store->file_ino_ = opened.st_ino;
  }
  sqlite3_busy_timeout(db, static_cast<int>(options.busy_timeout.count()));
  // WAL: readers never block the writer; FULL: every commit is fsynced before it returns.
  if (absl::Status s = Exec(db, path, "set journal mode", "PRAGMA journal_mode=WAL"); !s.ok())
    return s;
  if (absl::Status s = Exec(db, path, "set synchronous", "PRAGMA synchronous=FULL"); !s.ok())
    return s;
  if (absl::Status s = Exec(db, path, "enable foreign keys", "PRAGMA foreign_keys=ON"); !s.ok())
    return s;
  if (absl::Status s = store->Migrate(); !s.ok()) return s;
  if (absl::Status s = store->AbortRunning(); !s.ok()) return s;
  return store;
}

absl::Status Store::CheckFile() const {
  struct stat now {};
  if (::stat(path_.c_str(), &now) != 0) {
    return absl::FailedPreconditionError(absl::StrCat(
        "database ", path_, ": the file was removed while linecald ran (", std::strerror(errno),
        "); what is stored from now on is lost at the next start"));
  }
  if (now.st_dev != file_dev_ || now.st_ino != file_ino_) {
    return absl::FailedPreconditionError(
        absl::StrCat("database ", path_,
                     ": the file was replaced while linecald ran; what is stored from now "
                     "on goes to the old, unlinked file"));
  }
  return absl::OkStatus();
}

Store::~Store() {
  sqlite3_close(db_);
  ::close(lock_fd_);  // after SQLite is done with the file: the next Store may open it
}

absl::Status Store::Migrate() {
  Transaction tx(db_, path_);
  if (!tx.status().ok()) return tx.status();
  Statement version(db_, "PRAGMA user_version");
  if (const int rc = version.Step(); rc != SQLITE_ROW)
    return SqliteError(db_, path_, "read schema version", rc);
  const int64_t from = version.Int(0);
  if (from > kSchemaVersion) {
    return absl::FailedPreconditionError(absl::StrCat("database ", path_, ": schema version ", from,
                                                      " is newer than this linecald's (",
                                                      kSchemaVersion, "); refusing to open it"));
  }
  for (int64_t v = from; v < kSchemaVersion; ++v) {
    if (absl::Status s = Exec(db_, path_, "migrate schema", kMigrations[v]); !s.ok()) return s;
  }
  if (from != kSchemaVersion) {
    const std::string set = absl::StrCat("PRAGMA user_version=", kSchemaVersion);
    if (absl::Status s = Exec(db_, path_, "set schema version", set.c_str()); !s.ok()) return s;
  }
  return tx.Commit();
}

absl::Status Store::AbortRunning() {
  Transaction tx(db_, path_);
  if (!tx.status().ok()) return tx.status();
  const std::string select =
      absl::StrCat("SELECT ", kCycleColumns, " FROM cycles WHERE state = 'running' ORDER BY id");
  Statement running(db_, select.c_str());
  std::vector<StoredCycle> aborted;
  int step;
  while ((step = running.Step()) == SQLITE_ROW) aborted.push_back(ReadCycle(running));
  if (step != SQLITE_DONE) return SqliteError(db_, path_, "find running cycles", step);
  Statement s(db_,
              "UPDATE cycles SET state = 'aborted', verdict = 'error', "
              "reason = 'daemon_restarted', ended_ns = ?1 WHERE state = 'running'");
  // When the interruption was found: the real end is unknown, and 0 reads as "still running".
  s.Bind(1, static_cast<int64_t>(std::chrono::duration_cast<std::chrono::nanoseconds>(
                                     std::chrono::system_clock::now().time_since_epoch())
                                     .count()));
  if (const int rc = s.Step(); rc != SQLITE_DONE)
    return SqliteError(db_, path_, "abort running cycles", rc);
  for (const StoredCycle& c : aborted) {
    if (absl::Status q = Enqueue(c.id); !q.ok()) return q;
  }
  if (absl::Status c = tx.Commit(); !c.ok()) return c;
  aborted_at_open_ = std::move(aborted);
  return absl::OkStatus();
}

absl::StatusOr<int64_t> Store::BeginCycle(const StoredCycle& cycle) {
  std::lock_guard<std::mutex> lock(mutex_);
  Transaction tx(db_, path_);
  if (!tx.status().ok()) return tx.status();
  Statement car(db_,
                "INSERT INTO cars (vin, car_model_id, first_seen_ns) VALUES (?1, ?2, ?3) "
                "ON CONFLICT (vin) DO UPDATE SET car_model_id = excluded.car_model_id");
  car.Bind(1, cycle.vin).Bind(2, cycle.car_model_id).Bind(3, cycle.started_ns);
  if (const int rc = car.Step(); rc != SQLITE_DONE) return SqliteError(db_, path_, "store car", rc);
  Statement insert(
      db_,
      "INSERT INTO cycles (vin, car_model_id, state, verdict, started_ns, request_json, "
      "capture_path) VALUES (?1, ?2, 'running', '', ?3, ?4, ?5)");
  insert.Bind(1, cycle.vin)
      .Bind(2, cycle.car_model_id)
      .Bind(3, cycle.started_ns)
      .Bind(4, cycle.request_json)
      .Bind(5, cycle.capture_path);
  if (const int rc = insert.Step(); rc != SQLITE_DONE)
    return SqliteError(db_, path_, "store cycle", rc);
  const int64_t id = sqlite3_last_insert_rowid(db_);
  Statement last(db_, "UPDATE cars SET last_cycle_id = ?1 WHERE vin = ?2");
  last.Bind(1, id).Bind(2, cycle.vin);
  if (const int rc = last.Step(); rc != SQLITE_DONE)
    return SqliteError(db_, path_, "store car", rc);
  if (absl::Status s = tx.Commit(); !s.ok()) return s;
  return id;
}

absl::StatusOr<int64_t> Store::AppendEvent(const StoredEvent& event) {
  std::lock_guard<std::mutex> lock(mutex_);
  Transaction tx(db_, path_);
  if (!tx.status().ok()) return tx.status();
  Statement exists(
      db_,
      "SELECT COALESCE((SELECT MAX(sequence) + 1 FROM events WHERE cycle_id = ?1), 0), "
      "EXISTS (SELECT 1 FROM cycles WHERE id = ?1)");
  exists.Bind(1, event.cycle_id);
  if (const int rc = exists.Step(); rc != SQLITE_ROW)
    return SqliteError(db_, path_, "append event", rc);
  if (exists.Int(1) == 0) return absl::NotFoundError(absl::StrCat("no cycle ", event.cycle_id));
  const int64_t sequence = exists.Int(0);
  Statement insert(
      db_,
      "INSERT INTO events (cycle_id, sequence, time_ns, type, sensor, detail, verdict) "
      "VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7)");
  insert.Bind(1, event.cycle_id)
      .Bind(2, sequence)
      .Bind(3, event.time_ns)
      .Bind(4, std::string(EventTypeName(event.type)))
      .Bind(5, event.sensor)
      .Bind(6, event.detail)
      .Bind(7, std::string(VerdictName(event.verdict)));
  if (const int rc = insert.Step(); rc != SQLITE_DONE)
    return SqliteError(db_, path_, "append event", rc);
  if (absl::Status s = tx.Commit(); !s.ok()) return s;
  return sequence;
}

absl::Status Store::PutSensorResult(int64_t cycle_id, const StoredSensorResult& r) {
  std::lock_guard<std::mutex> lock(mutex_);
  Transaction tx(db_, path_);
  if (!tx.status().ok()) return tx.status();
  Statement state(db_, "SELECT state FROM cycles WHERE id = ?1");
  state.Bind(1, cycle_id);
  const int rc = state.Step();
  if (rc == SQLITE_DONE) return absl::NotFoundError(absl::StrCat("no cycle ", cycle_id));
  if (rc != SQLITE_ROW) return SqliteError(db_, path_, "store sensor result", rc);
  if (state.Text(0) != "running") {
    return absl::FailedPreconditionError(absl::StrCat("cycle ", cycle_id, " has ended (",
                                                      state.Text(0), "); its results are final"));
  }
  // A replaced result replaces its boards too; they go first, as they refer to it.
  Statement clear(db_, "DELETE FROM board_results WHERE cycle_id = ?1 AND sensor = ?2");
  clear.Bind(1, cycle_id).Bind(2, r.sensor);
  if (const int step = clear.Step(); step != SQLITE_DONE)
    return SqliteError(db_, path_, "store sensor result", step);
  Statement s(db_,
              "INSERT OR REPLACE INTO sensor_results VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, "
              "?8, ?9, ?10, ?11, ?12, ?13, ?14, ?15, ?16, ?17, ?18, ?19, ?20, ?21, ?22, ?23, ?24, "
              "?25, ?26, ?27, ?28, ?29, ?30, ?31, ?32)");
  s.Bind(1, cycle_id)
      .Bind(2, r.sensor)
      .Bind(3, SensorKindName(r.kind))
      .Bind(4, std::string(VerdictName(r.verdict)))
      .Bind(5, r.reason)
      .Bind(6, r.message)
      .Bind(7, Numbers(r.T_car_sensor));
  int i = 8;
  for (const MountingValues* m : {&r.measured, &r.deviation, &r.sigma}) {
    for (double v : {m->yaw_deg, m->pitch_deg, m->roll_deg, m->x_m, m->y_m, m->z_m}) s.Bind(i++, v);
  }
  s.Bind(26, r.residual_rms)
      .Bind(27, static_cast<int64_t>(r.features_used))
      .Bind(28, r.vanishing_point_u_px)
      .Bind(29, r.vanishing_point_v_px)
      .Bind(30, Numbers(r.ground_homography))
      .Bind(31, r.ranging_json)
      .Bind(32, r.elapsed_ns);
  if (const int step = s.Step(); step != SQLITE_DONE)
    return SqliteError(db_, path_, "store sensor result", step);
  if (absl::Status b = PutBoardResultsLocked(cycle_id, r); !b.ok()) return b;
  return tx.Commit();
}

absl::Status Store::PutBoardResultsLocked(int64_t cycle_id, const StoredSensorResult& r) {
  for (const StoredBoardResult& b : r.boards) {
    Statement s(db_, "INSERT INTO board_results VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7)");
    s.Bind(1, cycle_id)
        .Bind(2, r.sensor)
        .Bind(3, b.board)
        .Bind(4, static_cast<int64_t>(b.frames))
        .Bind(5, static_cast<int64_t>(b.frames_found))
        .Bind(6, static_cast<int64_t>(b.frames_partial))
        .Bind(7, b.residual_rms);
    if (const int step = s.Step(); step != SQLITE_DONE)
      return SqliteError(db_, path_, "store board results", step);
  }
  return absl::OkStatus();
}

absl::Status Store::EndCycle(int64_t cycle_id, CycleState state, Verdict verdict,
                             const std::string& reason, int64_t ended_ns) {
  if (state == CycleState::kRunning) {
    return absl::InvalidArgumentError("EndCycle: the end state cannot be running");
  }
  std::lock_guard<std::mutex> lock(mutex_);
  Transaction tx(db_, path_);
  if (!tx.status().ok()) return tx.status();
  Statement current(db_, "SELECT state FROM cycles WHERE id = ?1");
  current.Bind(1, cycle_id);
  const int rc = current.Step();
  if (rc == SQLITE_DONE) return absl::NotFoundError(absl::StrCat("no cycle ", cycle_id));
  if (rc != SQLITE_ROW) return SqliteError(db_, path_, "end cycle", rc);
  if (current.Text(0) != "running") {
    return absl::FailedPreconditionError(
        absl::StrCat("cycle ", cycle_id, " already ended (", current.Text(0), ")"));
  }
  Statement s(
      db_, "UPDATE cycles SET state = ?2, verdict = ?3, reason = ?4, ended_ns = ?5 WHERE id = ?1");
  s.Bind(1, cycle_id)
      .Bind(2, std::string(CycleStateName(state)))
      .Bind(3, std::string(VerdictName(verdict)))
      .Bind(4, reason)
      .Bind(5, ended_ns);
  if (const int step = s.Step(); step != SQLITE_DONE)
    return SqliteError(db_, path_, "end cycle", step);
  if (absl::Status q = Enqueue(cycle_id); !q.ok()) return q;
  return tx.Commit();
}

absl::Status Store::Enqueue(int64_t cycle_id) {
  if (!outbox_) return absl::OkStatus();
  Statement s(db_, "INSERT INTO outbox (cycle_id) VALUES (?1)");
  s.Bind(1, cycle_id);
  if (const int rc = s.Step(); rc != SQLITE_DONE) {
    return SqliteError(db_, path_, "queue cycle for the plant", rc);
  }
  return absl::OkStatus();
}

absl::StatusOr<StoredCycle> Store::GetCycle(int64_t cycle_id) {
  std::lock_guard<std::mutex> lock(mutex_);
  return ReadCycleLocked(cycle_id);
}

absl::StatusOr<StoredCycle> Store::ReadCycleLocked(int64_t cycle_id) {
  const std::string sql = absl::StrCat("SELECT ", kCycleColumns, " FROM cycles WHERE id = ?1");
  Statement s(db_, sql.c_str());
  s.Bind(1, cycle_id);
  const int rc = s.Step();
  if (rc == SQLITE_DONE) return absl::NotFoundError(absl::StrCat("no cycle ", cycle_id));
  if (rc != SQLITE_ROW) return SqliteError(db_, path_, "read cycle", rc);
  StoredCycle cycle = ReadCycle(s);

  Statement r(db_, "SELECT * FROM sensor_results WHERE cycle_id = ?1 ORDER BY sensor");
  r.Bind(1, cycle_id);
  int step;
  while ((step = r.Step()) == SQLITE_ROW) {
    StoredSensorResult x;
    x.sensor = r.Text(1);
    const std::optional<SensorKind> kind = ParseSensorKind(r.Text(2));
    // Only the store writes the column: another word is a damaged or foreign file.
    if (!kind) {
      return absl::DataLossError(absl::StrCat(path_, ": cycle ", cycle_id, " has sensor ",
                                              QuoteInput(r.Text(1)), " of unknown kind ",
                                              QuoteInput(r.Text(2))));
    }
    x.kind = *kind;
    x.verdict = ParseVerdict(r.Text(3));
    x.reason = r.Text(4);
    x.message = r.Text(5);
    x.T_car_sensor = ParseNumbers(r.Text(6));
    int col = 7;
    for (MountingValues* m : {&x.measured, &x.deviation, &x.sigma}) {
      for (double* v : {&m->yaw_deg, &m->pitch_deg, &m->roll_deg, &m->x_m, &m->y_m, &m->z_m})
        *v = r.Real(col++);
    }
    x.residual_rms = r.Real(25);
    x.features_used = static_cast<int>(r.Int(26));
    if (!r.IsNull(27)) x.vanishing_point_u_px = r.Real(27);
    if (!r.IsNull(28)) x.vanishing_point_v_px = r.Real(28);
    x.ground_homography = ParseNumbers(r.Text(29));
    x.ranging_json = r.Text(30);
    x.elapsed_ns = r.Int(31);
    cycle.sensors.push_back(std::move(x));
  }
  if (step != SQLITE_DONE) return SqliteError(db_, path_, "read sensor results", step);
  Statement b(db_,
              "SELECT sensor, board, frames, frames_found, frames_partial, residual_rms "
              "FROM board_results WHERE cycle_id = ?1 ORDER BY sensor, board");
  b.Bind(1, cycle_id);
  // Both in sensor order: one pass matches each board to its sensor.
  auto sensor = cycle.sensors.begin();
  while ((step = b.Step()) == SQLITE_ROW) {
    while (sensor != cycle.sensors.end() && sensor->sensor < b.Text(0)) ++sensor;
    if (sensor == cycle.sensors.end() || sensor->sensor != b.Text(0)) continue;
    sensor->boards.push_back(ReadBoard(b, 1));
  }
  if (step != SQLITE_DONE) return SqliteError(db_, path_, "read board results", step);
  return cycle;
}

absl::StatusOr<std::vector<StoredEvent>> Store::Events(int64_t cycle_id) {
  std::lock_guard<std::mutex> lock(mutex_);
  return ReadEventsLocked(cycle_id);
}

absl::StatusOr<std::vector<StoredEvent>> Store::ReadEventsLocked(int64_t cycle_id) {
  Statement s(
      db_,
      "SELECT sequence, time_ns, type, sensor, detail, verdict FROM events WHERE cycle_id = ?1 "
      "ORDER BY sequence");
  s.Bind(1, cycle_id);
  std::vector<StoredEvent> events;
  int rc;
  while ((rc = s.Step()) == SQLITE_ROW) {
    const std::optional<EventType> type = ParseEventType(s.Text(2));
    // Only AppendEvent writes the column: another word is a damaged or foreign file.
    if (!type) {
      return absl::DataLossError(absl::StrCat(
          path_, ": cycle ", cycle_id, " has an event of unknown type ", QuoteInput(s.Text(2))));
    }
    events.push_back(
        {cycle_id, s.Int(0), s.Int(1), *type, s.Text(3), s.Text(4), ParseVerdict(s.Text(5))});
  }
  if (rc != SQLITE_DONE) return SqliteError(db_, path_, "read events", rc);
  return events;
}

absl::StatusOr<CyclePage> Store::ListCycles(const CycleFilter& filter) {
  // 1000: a page stays a few hundred kilobytes; the client asks for the next one.
  if (filter.page_size < 1 || filter.page_size > 1000) {
    return absl::InvalidArgumentError(
        absl::StrCat("page_size ", filter.page_size, " is outside 1..1000"));
  }
  // The token is the (started_ns, id) of the page's last cycle: the next page starts strictly
  // after it in the newest-first order, so inserts between pages never repeat or skip a row.
  int64_t after_started = INT64_MAX, after_id = INT64_MAX;
  if (!filter.page_token.empty()) {
    std::vector<std::string> parts = absl::StrSplit(filter.page_token, '.');
    if (parts.size() != 2 || !absl::SimpleAtoi(parts[0], &after_started) ||
        !absl::SimpleAtoi(parts[1], &after_id)) {
      return absl::InvalidArgumentError(
          absl::StrCat("page_token ", QuoteInput(filter.page_token), " is malformed"));
    }
  }
  std::lock_guard<std::mutex> lock(mutex_);
  const std::string sql = absl::StrCat(
      "SELECT ", kCycleColumns, " FROM cycles WHERE (?1 = '' OR vin = ?1) AND started_ns >= ?2 ",
      "AND (?3 = 0 OR started_ns < ?3) AND (?4 = 0 OR verdict = ?5) ",
      "AND (started_ns < ?6 OR (started_ns = ?6 AND id < ?7)) ",
      "ORDER BY started_ns DESC, id DESC LIMIT ?8");
  Statement s(db_, sql.c_str());
  s.Bind(1, filter.vin)
      .Bind(2, filter.since_ns)
      .Bind(3, filter.until_ns)
      .Bind(4, static_cast<int64_t>(filter.verdict.has_value()))
      .Bind(5, std::string(VerdictName(filter.verdict)))
      .Bind(6, after_started)
      .Bind(7, after_id)
      // One more than the page: whether it exists says if there is a next page.
      .Bind(8, static_cast<int64_t>(filter.page_size) + 1);
  CyclePage page;
  int rc;
  while ((rc = s.Step()) == SQLITE_ROW) page.cycles.push_back(ReadCycle(s));
  if (rc != SQLITE_DONE) return SqliteError(db_, path_, "list cycles", rc);
  if (page.cycles.size() > static_cast<size_t>(filter.page_size)) {
    page.cycles.pop_back();
    const StoredCycle& last = page.cycles.back();
    page.next_page_token = absl::StrCat(last.started_ns, ".", last.id);
  }
  return page;
}

absl::StatusOr<std::vector<TrendRow>> Store::RecentSolvedResults(int cycles) {
  // 100,000: ten times the trends page's largest view, far below what fits in memory.
  if (cycles < 1 || cycles > 100000) {
    return absl::InvalidArgumentError(
        absl::StrCat("cycles = ", cycles, ": must be in [1, 100000]"));
  }
  std::lock_guard<std::mutex> lock(mutex_);
  Statement s(
      db_,
      "SELECT c.id, c.started_ns, c.car_model_id, r.sensor, r.d_yaw_deg, r.d_pitch_deg, "
      "r.d_roll_deg, r.d_x_m, r.d_y_m, r.d_z_m, r.residual_rms FROM (SELECT id, started_ns, "
      "car_model_id FROM cycles WHERE state = 'done' ORDER BY id DESC LIMIT ?1) c "
      "JOIN sensor_results r ON r.cycle_id = c.id WHERE r.T_car_sensor <> '' "
      "ORDER BY c.id, r.sensor");
  s.Bind(1, static_cast<int64_t>(cycles));
  std::vector<TrendRow> rows;
  int rc;
  while ((rc = s.Step()) == SQLITE_ROW) {
    TrendRow row;
    row.cycle_id = s.Int(0);
    row.started_ns = s.Int(1);
    row.car_model_id = s.Text(2);
    row.sensor = s.Text(3);
    MountingValues& d = row.deviation;
    int col = 4;
    for (double* v : {&d.yaw_deg, &d.pitch_deg, &d.roll_deg, &d.x_m, &d.y_m, &d.z_m})
      *v = s.Real(col++);
    row.residual_rms = s.Real(10);
    rows.push_back(std::move(row));
  }
  if (rc != SQLITE_DONE) return SqliteError(db_, path_, "read trends", rc);
  return rows;
}

absl::StatusOr<std::vector<BoardTrendRow>> Store::RecentBoardResults(int cycles) {
  if (cycles < 1 || cycles > 100000) {  // as RecentSolvedResults
    return absl::InvalidArgumentError(
        absl::StrCat("cycles = ", cycles, ": must be in [1, 100000]"));
  }
  std::lock_guard<std::mutex> lock(mutex_);
  Statement s(db_,
              "SELECT c.id, c.started_ns, c.car_model_id, b.sensor, r.T_car_sensor <> '', b.board, "
              "b.frames, b.frames_found, b.frames_partial, b.residual_rms FROM (SELECT id, "
              "started_ns, car_model_id FROM cycles WHERE state = 'done' ORDER BY id DESC "
              "LIMIT ?1) c JOIN board_results b ON b.cycle_id = c.id JOIN sensor_results r ON "
              "r.cycle_id = b.cycle_id AND r.sensor = b.sensor ORDER BY c.id, b.sensor, b.board");
  s.Bind(1, static_cast<int64_t>(cycles));
  std::vector<BoardTrendRow> rows;
  int rc;
  while ((rc = s.Step()) == SQLITE_ROW) {
    rows.push_back({s.Int(0), s.Int(1), s.Text(2), s.Text(3), s.Int(4) != 0, ReadBoard(s, 5)});
  }
  if (rc != SQLITE_DONE) return SqliteError(db_, path_, "read board trends", rc);
  return rows;
}

absl::StatusOr<std::optional<int64_t>> Store::RunningCycle() {
  std::lock_guard<std::mutex> lock(mutex_);
  Statement s(db_, "SELECT id FROM cycles WHERE state = 'running' ORDER BY id DESC LIMIT 1");
  const int rc = s.Step();
  if (rc == SQLITE_DONE) return std::optional<int64_t>();
  if (rc != SQLITE_ROW) return SqliteError(db_, path_, "find running cycle", rc);
  return std::optional<int64_t>(s.Int(0));
}

absl::StatusOr<std::vector<OutboxEntry>> Store::ReadOutbox(int limit) {
  if (limit < 1) {
    return absl::InvalidArgumentError(absl::StrCat("ReadOutbox: limit ", limit, " < 1"));
  }
  std::lock_guard<std::mutex> lock(mutex_);
  // One read transaction: the cycles and their events as of one moment.
  if (absl::Status s = Exec(db_, path_, "begin", "BEGIN"); !s.ok()) return s;
  absl::StatusOr<std::vector<OutboxEntry>> entries = ReadOutboxLocked(limit);
  sqlite3_exec(db_, "COMMIT", nullptr, nullptr, nullptr);  // a read: nothing to keep or lose
  return entries;
}

absl::StatusOr<std::vector<OutboxEntry>> Store::ReadOutboxLocked(int limit) {
  Statement queued(db_, "SELECT seq, cycle_id FROM outbox ORDER BY seq LIMIT ?1");
  queued.Bind(1, static_cast<int64_t>(limit));
  std::vector<OutboxEntry> entries;
  int rc;
  while ((rc = queued.Step()) == SQLITE_ROW) {
    OutboxEntry& e = entries.emplace_back();
    e.seq = queued.Int(0);
    e.cycle.id = queued.Int(1);
  }
  if (rc != SQLITE_DONE) return SqliteError(db_, path_, "read the outbox", rc);
  for (OutboxEntry& e : entries) {
    absl::StatusOr<StoredCycle> cycle = ReadCycleLocked(e.cycle.id);
    if (!cycle.ok()) return cycle.status();
    absl::StatusOr<std::vector<StoredEvent>> events = ReadEventsLocked(e.cycle.id);
    if (!events.ok()) return events.status();
    e.cycle = *std::move(cycle);
    e.events = *std::move(events);
  }
  return entries;
}

absl::Status Store::MarkShipped(int64_t seq) {
  std::lock_guard<std::mutex> lock(mutex_);
  Statement s(db_, "DELETE FROM outbox WHERE seq <= ?1");
  s.Bind(1, seq);
  if (const int rc = s.Step(); rc != SQLITE_DONE) {
    return SqliteError(db_, path_, "mark cycles shipped", rc);
  }
  return absl::OkStatus();
}

absl::StatusOr<OutboxBacklog> Store::Backlog() {
  std::lock_guard<std::mutex> lock(mutex_);
  Statement s(db_,
              "SELECT (SELECT COUNT(*) FROM outbox), COALESCE((SELECT c.ended_ns FROM outbox o "
              "JOIN cycles c ON c.id = o.cycle_id ORDER BY o.seq LIMIT 1), 0)");
  if (const int rc = s.Step(); rc != SQLITE_ROW) {
    return SqliteError(db_, path_, "read the outbox backlog", rc);
  }
  return OutboxBacklog{s.Int(0), s.Int(1)};
}

absl::Status Store::IntegrityCheck() {
  std::lock_guard<std::mutex> lock(mutex_);
  Statement s(db_, "PRAGMA integrity_check");
  const int rc = s.Step();
  if (rc != SQLITE_ROW) return SqliteError(db_, path_, "integrity check", rc);
  const std::string result = s.Text(0);
  if (result != "ok")
    return absl::DataLossError(absl::StrCat("database ", path_, ": integrity check: ", result));
  return absl::OkStatus();
}

}  // namespace linecal
