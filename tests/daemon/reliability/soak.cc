// linecal-soak: many cycles of a real StationCore (replay source, a real SQLite file) with
// faults injected, checking that every cycle ends stored with a state and a reason, that the
// database stays intact, and that threads, descriptors and memory do not leak
// (docs/acceptance.md, "soak"; docs/reliability.md). `tools/soak` runs it.
//
//   linecal-soak [--cycles N] [--seed S] [--sensors a,b,...] [--rss-from K] [--dir DIR]
//
// Cycle 0 is clean: its results are what every undisturbed sensor must give again, bit for
// bit (a replayed capture computes the same every time). Cycles 1..F inject each fault of
// the table once, in order; the rest draw a fault by weight from a generator seeded with S.
// (`linecal-soak --hold-lock DB` is the soak's own helper process that locks the database.)
// Exit status 0 when every expectation and every final check held, 1 otherwise, 2 for bad
// flags or a setup that failed.
//
// The faults are a table (Faults()); each runs one cycle with its fault and checks the
// outcome it must have. A live-source fault (a camera that vanishes, a silent CAN bus) is one
// more entry, run on a core configured with that source.
#include <fcntl.h>
#include <malloc.h>
#include <spawn.h>
#include <sqlite3.h>
#include <sys/mount.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <map>
#include <optional>
#include <random>
#include <string>
#include <thread>
#include <tuple>
#include <vector>

#include "absl/status/statusor.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "daemon/core/station_core.h"
#include "station/capture/capture.h"
#include "tests/daemon/reliability/reliability_support.h"
#include "tests/daemon/reliability/soak_live.h"

namespace linecal::reliability {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

constexpr char kCarId[] = "soak";
// The store's busy timeout in the soak: long enough that a briefly locked database is waited
// out, short enough that the locked-database faults cost seconds, not minutes.
constexpr std::chrono::milliseconds kBusyTimeout{500};

// The run's state the faults work on.
struct Soak {
  StationCore* core = nullptr;
  StationCoreConfig config;  // the core's: the storage faults build cores of their own from it
  fs::path dir;              // the scratch directory
  fs::path capture;          // the replayed capture (data_root/replay), restored after each fault
  fs::path pristine;         // the untouched copy
  Capture layout;            // the pristine capture as read: which files each sensor has
  std::string db_path;
  std::mt19937_64 rng;
  CycleRequest request;
  Clock::duration clean_time{};       // of cycle 0
  StoredCycle clean;                  // cycle 0, elapsed times zeroed
  std::vector<std::int64_t> started;  // every id StartCycle returned
  std::vector<std::string> changed;   // capture files a fault changed (relative)
  std::vector<Clock::duration> cycle_times;
  LiveRig live;                         // the car's LiDARs and radars on live sources
  std::optional<LiveCycle> live_clean;  // the first clean live cycle: the live faults' reference
};

absl::Status Violation(const std::string& what) { return absl::InternalError(what); }

double Uniform(Soak& s, double lo, double hi) {
  return std::uniform_real_distribution<double>(lo, hi)(s.rng);
}
size_t Pick(Soak& s, size_t n) { return std::uniform_int_distribution<size_t>(0, n - 1)(s.rng); }

// Every sensor of the capture of `kind`.
std::vector<const CaptureSensor*> SensorsOf(const Soak& s, SensorKind kind) {
  std::vector<const CaptureSensor*> out;
  for (const CaptureSensor& c : s.layout.manifest.sensors) {
    if (c.kind == kind) out.push_back(&c);
  }
  return out;
}

// A file of the capture about to be changed: remembered, to be restored from the pristine copy.
fs::path Change(Soak& s, const std::string& relative) {
  s.changed.push_back(relative);
  return s.capture / relative;
}

absl::Status Restore(Soak& s) {
  for (const std::string& rel : s.changed) {
    std::error_code ec;
    fs::copy_file(s.pristine / rel, s.capture / rel, fs::copy_options::overwrite_existing, ec);
    if (ec) return Violation(absl::StrCat("restore ", rel, ": ", ec.message()));
  }
  s.changed.clear();
  return absl::OkStatus();
}

// Another process holding the database's write lock (BEGIN EXCLUSIVE) for as long as this
// object lives: linecal-soak itself, run as `linecal-soak --hold-lock DB` (HoldLock below). It
// is a process, not a second connection of ours, because SQLite keeps a closed connection's
// descriptor open while another connection of the same process holds a lock on the file.
// The holder starts (exec, SQLite open) before it locks, which takes 0.1-0.2 s: with `take`
// false the constructor returns once it is ready, and Take() then locks within milliseconds
// (a cycle of the smoke's three sensors stores its first result 0.2 s after its start).
class DatabaseLock {
 public:
  explicit DatabaseLock(const std::string& db_path, bool take = true) {
    int to_child[2], from_child[2];
    if (::pipe2(to_child, O_CLOEXEC) != 0) return;
    if (::pipe2(from_child, O_CLOEXEC) != 0) {
      ::close(to_child[0]);
      ::close(to_child[1]);
      return;
    }
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_adddup2(&actions, to_child[0], STDIN_FILENO);
    posix_spawn_file_actions_adddup2(&actions, from_child[1], STDOUT_FILENO);
    // /proc/self/exe: this very binary, even when a rebuild has replaced the file meanwhile.
    std::string self = "/proc/self/exe", flag = "--hold-lock", db = db_path;
    char* argv[] = {self.data(), flag.data(), db.data(), nullptr};
    const bool spawned = posix_spawn(&pid_, self.c_str(), &actions, nullptr, argv, environ) == 0;
    posix_spawn_file_actions_destroy(&actions);
    ::close(to_child[0]);
    ::close(from_child[1]);
    release_ = to_child[1];
    answers_ = from_child[0];
    char answer = 0;
    ready_ = spawned && ::read(answers_, &answer, 1) == 1 && answer == 'R';
    if (!spawned) pid_ = -1;
    if (take) Take();
  }
  // Locks (once the holder is ready); held() says whether it did.
  void Take() {
    char answer = 0;
    held_ = ready_ && ::write(release_, "G", 1) == 1 && ::read(answers_, &answer, 1) == 1 &&
            answer == 'L';
  }
  // Closing the pipe tells the holder to commit and exit.
  ~DatabaseLock() {
    ::close(release_);
    ::close(answers_);
    if (pid_ > 0) ::waitpid(pid_, nullptr, 0);
  }
  bool held() const { return held_; }

 private:
  pid_t pid_ = -1;
  int release_ = -1;
  int answers_ = -1;
  bool ready_ = false;
  bool held_ = false;
};

// The lock holder's side: opens the database and says 'R' on stdout; on a byte from stdin
// takes the lock and says 'L' (or 'E'); holds it until stdin closes, commits.
int HoldLock(const char* db_path) {
  sqlite3* db = nullptr;
  const bool opened =
      sqlite3_open(db_path, &db) == SQLITE_OK && sqlite3_busy_timeout(db, 10000) == SQLITE_OK;
  if (::write(STDOUT_FILENO, "R", 1) != 1) return 1;
  char byte;
  if (::read(STDIN_FILENO, &byte, 1) != 1) return 1;
  const bool held =
      opened && sqlite3_exec(db, "BEGIN EXCLUSIVE", nullptr, nullptr, nullptr) == SQLITE_OK;
  const char answer = held ? 'L' : 'E';
  if (::write(STDOUT_FILENO, &answer, 1) != 1) return 1;
  while (::read(STDIN_FILENO, &byte, 1) > 0) {
  }
  if (held) sqlite3_exec(db, "COMMIT", nullptr, nullptr, nullptr);
  sqlite3_close(db);
  return held ? 0 : 1;
}

// Starts the cycle, runs `during` while it runs, waits for its stored end and reads it.
absl::StatusOr<StoredCycle> RunOneCycle(
    Soak& s, const std::function<absl::Status(std::int64_t)>& during = nullptr) {
  const Clock::time_point t0 = Clock::now();
  absl::StatusOr<std::int64_t> id = s.core->StartCycle(s.request);
  if (!id.ok()) return Violation(absl::StrCat("StartCycle: ", id.status().ToString()));
  s.started.push_back(*id);
  const absl::Status d = during ? during(*id) : absl::OkStatus();
  s.core->WaitIdle();
  s.cycle_times.push_back(Clock::now() - t0);
  if (!d.ok()) return d;
  absl::StatusOr<StoredCycle> cycle = s.core->GetCycle(*id);
  if (!cycle.ok())
    return Violation(absl::StrCat("GetCycle ", *id, ": ", cycle.status().ToString()));
  for (StoredSensorResult& r : cycle->sensors) r.elapsed_ns = 0;
  return cycle;
}

// The rule for every stored cycle: ended, with end time, and a reason unless it passed.
absl::Status ExpectEnded(const StoredCycle& c) {
  if (c.state == CycleState::kRunning)
    return Violation(absl::StrCat("cycle ", c.id, " still running"));
  if (c.ended_ns < c.started_ns || c.started_ns <= 0) {
    return Violation(absl::StrCat("cycle ", c.id, ": ended_ns ", c.ended_ns, " before started_ns ",
                                  c.started_ns));
  }
  const bool passed = c.state == CycleState::kDone && c.verdict == Verdict::kPass;
  if (!passed && c.reason.empty()) {
    return Violation(absl::StrCat("cycle ", c.id, " (", CycleStateName(c.state), ", ",
                                  VerdictName(c.verdict), ") has no reason"));
  }
  return absl::OkStatus();
}

// Every sensor but `except` gave what it gave in cycle 0.
absl::Status ExpectSensorsAsClean(const Soak& s, const StoredCycle& c,
                                  const std::string& except = "") {
  if (c.state != CycleState::kDone) {
    return Violation(absl::StrCat("cycle ", c.id, ": ", CycleStateName(c.state), " (", c.reason,
                                  "), expected done"));
  }
  if (c.sensors.size() != s.clean.sensors.size()) {
    return Violation(absl::StrCat("cycle ", c.id, ": ", c.sensors.size(),
                                  " sensor results, expected ", s.clean.sensors.size(), " (",
                                  c.reason, ")"));
  }
  for (size_t i = 0; i < c.sensors.size(); ++i) {
    if (c.sensors[i].sensor != except && !(c.sensors[i] == s.clean.sensors[i])) {
      return Violation(absl::StrCat("cycle ", c.id, ": ", c.sensors[i].sensor,
                                    " differs from cycle 0 (", VerdictName(c.sensors[i].verdict),
                                    " ", c.sensors[i].reason, ")"));
    }
  }
  return absl::OkStatus();
}

absl::Status ExpectClean(const Soak& s, const StoredCycle& c) {
  if (absl::Status st = ExpectSensorsAsClean(s, c); !st.ok()) return st;
  if (c.verdict != s.clean.verdict || c.reason != s.clean.reason) {
    return Violation(absl::StrCat("cycle ", c.id, ": verdict ", VerdictName(c.verdict), " '",
                                  c.reason, "', cycle 0 had ", VerdictName(s.clean.verdict), " '",
                                  s.clean.reason, "'"));
  }
  return absl::OkStatus();
}

// The one damaged sensor is in error with data_unreadable naming the file; the others as in
// cycle 0; the cycle done in error with the sensor in its reason.
absl::Status ExpectUnreadable(const Soak& s, const StoredCycle& c, const std::string& sensor,
                              const std::string& file) {
  if (absl::Status st = ExpectSensorsAsClean(s, c, sensor); !st.ok()) return st;
  for (const StoredSensorResult& r : c.sensors) {
    if (r.sensor != sensor) continue;
    if (r.verdict != Verdict::kError || r.reason != "data_unreadable") {
      return Violation(absl::StrCat("cycle ", c.id, ": ", sensor, " ", VerdictName(r.verdict), " '",
                                    r.reason, "', expected error data_unreadable (", file, ")"));
    }
    if (r.message.find(fs::path(file).filename().string()) == std::string::npos) {
      return Violation(absl::StrCat("cycle ", c.id, ": ", sensor, "'s message does not name ", file,
                                    ": ", r.message));
    }
  }
  if (c.verdict != Verdict::kError ||
      c.reason.find(sensor + ":data_unreadable") == std::string::npos) {
    return Violation(absl::StrCat("cycle ", c.id, ": ", VerdictName(c.verdict), " '", c.reason,
                                  "', expected error with ", sensor, ":data_unreadable"));
  }
  return absl::OkStatus();
}

// One fault: runs one cycle (or attempts one) with it and checks the outcome it must have;
// returns the outcome's name for the summary, or a violated expectation.
struct Fault {
  std::string name;
  int weight;  // relative frequency after the first pass over the table
  std::string what;
  std::function<absl::StatusOr<std::string>(Soak&)> run;
};

absl::StatusOr<std::string> Clean(Soak& s) {
  absl::StatusOr<StoredCycle> c = RunOneCycle(s);
  if (!c.ok()) return c.status();
  if (absl::Status st = ExpectClean(s, *c); !st.ok()) return st;
  return std::string("done as cycle 0");
}

// A camera frame, LiDAR scan or CAN log damaged by `damage` (given the file's bytes).
absl::StatusOr<std::string> DamagedSensor(Soak& s, SensorKind kind,
                                          const std::function<void(std::string*)>& damage) {
  const std::vector<const CaptureSensor*> sensors = SensorsOf(s, kind);
  if (sensors.empty()) return std::string("skipped: no sensor of this kind");
  const CaptureSensor& sensor = *sensors[Pick(s, sensors.size())];
  const std::string rel = kind == SensorKind::kRadar
                              ? sensor.can_log->path
                              : sensor.frames[Pick(s, sensor.frames.size())].path;
  const fs::path path = Change(s, rel);
  std::string bytes;
  {
    std::ifstream in(path, std::ios::binary);
    bytes.assign(std::istreambuf_iterator<char>(in), {});
  }
  damage(&bytes);
  std::ofstream(path, std::ios::binary | std::ios::trunc) << bytes;
  absl::StatusOr<StoredCycle> c = RunOneCycle(s);
  if (!c.ok()) return c.status();
  if (absl::Status st = ExpectUnreadable(s, *c, sensor.name, rel); !st.ok()) return st;
  return std::string("sensor error data_unreadable, others as cycle 0");
}

absl::StatusOr<std::string> CorruptCameraFrame(Soak& s) {
  return DamagedSensor(s, SensorKind::kCamera, [&](std::string* png) {
    // 32 random bytes in the second half: inside the compressed image data, whose chunk CRCs
    // and zlib checks must catch it.
    for (int i = 0; i < 32; ++i) {
      (*png)[png->size() / 2 + Pick(s, png->size() / 2)] = static_cast<char>(Pick(s, 256));
    }
  });
}

absl::StatusOr<std::string> TruncatedCameraFrame(Soak& s) {
  return DamagedSensor(s, SensorKind::kCamera, [&](std::string* png) {
    png->resize(static_cast<size_t>(png->size() * Uniform(s, 0.1, 0.9)));
  });
}

absl::StatusOr<std::string> TruncatedLidarScan(Soak& s) {
  return DamagedSensor(s, SensorKind::kLidar, [&](std::string* pcd) {
    pcd->resize(static_cast<size_t>(pcd->size() * Uniform(s, 0.3, 0.95)));
  });
}

absl::StatusOr<std::string> TruncatedCanLog(Soak& s) {
  return DamagedSensor(s, SensorKind::kRadar, [&](std::string* log) {
    // Cut inside the "(seconds.micros)" stamp of a line in the middle: a partial last line.
    const size_t from = log->size() / 4 + Pick(s, log->size() / 2);
    const size_t line = log->rfind('\n', from);
    const size_t start = line == std::string::npos ? 0 : line + 1;
    log->resize(start + 1 + Pick(s, 10));
  });
}

absl::StatusOr<std::string> MissingFile(Soak& s) {
  std::vector<std::string> files = {kCaptureManifestFile, kCaptureStationFile, kCaptureCarFile};
  for (const CaptureSensor& c : s.layout.manifest.sensors) {
    for (const CaptureFile& f : c.frames) files.push_back(f.path);
    if (c.packets) files.push_back(c.packets->path);
    if (c.can_log) files.push_back(c.can_log->path);
  }
  const std::string rel = files[Pick(s, files.size())];
  fs::remove(Change(s, rel));
  absl::StatusOr<StoredCycle> c = RunOneCycle(s);
  if (!c.ok()) return c.status();
  if (c->state != CycleState::kDone || c->verdict != Verdict::kError ||
      c->reason.rfind("capture_unreadable: ", 0) != 0 || !c->sensors.empty()) {
    return Violation(absl::StrCat("cycle ", c->id, " without ", rel, ": ", CycleStateName(c->state),
                                  " ", VerdictName(c->verdict), " '", c->reason, "' with ",
                                  c->sensors.size(),
                                  " sensors, expected done error capture_unreadable"));
  }
  if (c->reason.find(fs::path(rel).filename().string()) == std::string::npos) {
    return Violation(
        absl::StrCat("cycle ", c->id, ": the reason does not name ", rel, ": ", c->reason));
  }
  return std::string("done error capture_unreadable naming the file");
}

absl::StatusOr<std::string> DatabaseLockedBriefly(Soak& s) {
  absl::StatusOr<StoredCycle> c = RunOneCycle(s, [&](std::int64_t) {
    DatabaseLock lock(s.db_path);
    if (!lock.held()) return Violation("could not lock the database");
    // Under the busy timeout: the cycle's writes wait for it and go through.
    std::this_thread::sleep_for(kBusyTimeout / 3);
    return absl::OkStatus();
  });
  if (!c.ok()) return c.status();
  if (absl::Status st = ExpectClean(s, *c); !st.ok()) return st;
  return std::string("done as cycle 0");
}

absl::StatusOr<std::string> DatabaseLockedAtStart(Soak& s) {
  absl::StatusOr<std::int64_t> newest_before;
  {
    CycleFilter newest;
    newest.page_size = 1;
    absl::StatusOr<CyclePage> page = s.core->ListCycles(newest);
    if (!page.ok()) return page.status();
    newest_before = page->cycles.empty() ? 0 : page->cycles[0].id;
    DatabaseLock lock(s.db_path);
    if (!lock.held()) return Violation("could not lock the database");
    const absl::StatusOr<std::int64_t> id = s.core->StartCycle(s.request);
    if (id.ok()) {
      s.started.push_back(*id);
      return Violation(absl::StrCat("StartCycle on a locked database started cycle ", *id));
    }
    if (id.status().code() != absl::StatusCode::kUnavailable ||
        id.status().message().find(s.db_path) == std::string::npos) {
      return Violation(absl::StrCat("StartCycle on a locked database: ", id.status().ToString(),
                                    ", expected UNAVAILABLE naming the database"));
    }
  }
  CycleFilter newest;
  newest.page_size = 1;
  absl::StatusOr<CyclePage> page = s.core->ListCycles(newest);
  if (!page.ok()) return page.status();
  if ((page->cycles.empty() ? 0 : page->cycles[0].id) != *newest_before) {
    return Violation("a refused StartCycle left a cycle in the store");
  }
  if (s.core->Status().running_cycle)
    return Violation("the station is busy after a refused StartCycle");
  return std::string("refused UNAVAILABLE, nothing stored");
}

absl::StatusOr<std::string> DatabaseLockedMidCycle(Soak& s) {
  // Ready before the cycle starts, locked right after: the cycle meets the lock for sure.
  std::optional<DatabaseLock> lock;
  lock.emplace(s.db_path, /*take=*/false);
  absl::StatusOr<StoredCycle> c = RunOneCycle(s, [&](std::int64_t id) {
    // Released when this returns, whatever it returns: the cycle's end waits for it.
    struct Release {
      std::optional<DatabaseLock>& lock;
      ~Release() { lock.reset(); }
    } release{lock};
    lock->Take();
    if (!lock->held()) return Violation("could not lock the database");
    // Longer than two whole cycles: the cycle meets the lock when it stores its results.
    std::this_thread::sleep_for(2 * s.clean_time + 4 * kBusyTimeout);
    if (s.core->Status().running_cycle != id) {
      return Violation(
          absl::StrCat("cycle ", id, ": the station went idle while its end could not be stored"));
    }
    return absl::OkStatus();
  });
  if (!c.ok()) return c.status();
  if (c->state != CycleState::kDone || c->verdict != Verdict::kError ||
      c->reason.rfind("store_unavailable: ", 0) != 0) {
    return Violation(absl::StrCat("cycle ", c->id, " under a lock: ", CycleStateName(c->state), " ",
                                  VerdictName(c->verdict), " '", c->reason,
                                  "', expected done error store_unavailable"));
  }
  return std::string("done error store_unavailable, stored after the lock");
}

absl::StatusOr<std::string> CancelAtRandom(Soak& s) {
  absl::Status cancel;
  absl::StatusOr<StoredCycle> c = RunOneCycle(s, [&](std::int64_t id) {
    // Anywhere from the start to a little after a clean cycle's end.
    std::this_thread::sleep_for(
        std::chrono::duration_cast<Clock::duration>(s.clean_time * Uniform(s, 0, 1.2)));
    cancel = s.core->CancelCycle(id);
    return absl::OkStatus();
  });
  if (!c.ok()) return c.status();
  if (cancel.ok()) {
    if (c->state != CycleState::kCancelled || c->verdict != Verdict::kError ||
        c->reason != "cancelled") {
      return Violation(absl::StrCat("cycle ", c->id, ": cancel accepted, yet ",
                                    CycleStateName(c->state), " ", VerdictName(c->verdict), " '",
                                    c->reason, "'"));
    }
    return std::string("cancel accepted, cancelled");
  }
  if (cancel.code() != absl::StatusCode::kFailedPrecondition) {
    return Violation(absl::StrCat("CancelCycle of the running cycle: ", cancel.ToString()));
  }
  if (absl::Status st = ExpectClean(s, *c); !st.ok()) return st;
  return std::string("cancel refused after the end, done as cycle 0");
}

absl::StatusOr<std::string> InvalidRequests(Soak& s) {
  struct Bad {
    std::function<void(CycleRequest*)> change;
    std::string field;
  };
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const std::vector<Bad> bad = {
      {[](CycleRequest* r) { r->vin = "1M8GDM9AXKP04278O"; }, "vin"},  // the letter O
      {[](CycleRequest* r) { r->vin = "1M8GDM9AXKP042789"; }, "vin"},  // wrong check digit
      {[](CycleRequest* r) { r->vin.clear(); }, "vin"},
      {[](CycleRequest* r) { r->car_model_id = "sedan"; }, "car_model_id"},
      {[](CycleRequest* r) { r->aligner.longitudinal_offset_m = 1e9; },
       "aligner.longitudinal_offset_m"},
      {[=](CycleRequest* r) { r->aligner.lateral_offset_m = nan; }, "aligner.lateral_offset_m"},
      {[](CycleRequest* r) {
         r->aligner.thrust_angle_rad = std::numeric_limits<double>::infinity();
       },
       "aligner.thrust_angle_deg"},
      {[](CycleRequest* r) { r->frames_per_sensor = -1; }, "options.frames_per_sensor"},
      {[](CycleRequest* r) { r->frames_per_sensor = 101; }, "options.frames_per_sensor"},
  };
  for (const Bad& b : bad) {
    CycleRequest r = s.request;
    b.change(&r);
    const absl::StatusOr<std::int64_t> id = s.core->StartCycle(r);
    if (id.ok()) s.started.push_back(*id);
    if (id.status().code() != absl::StatusCode::kInvalidArgument ||
        id.status().message().rfind(b.field, 0) != 0) {
      return Violation(absl::StrCat("bad ", b.field, ": ", id.status().ToString(),
                                    ", expected INVALID_ARGUMENT naming it"));
    }
  }
  const std::int64_t unknown = (s.started.empty() ? 0 : s.started.back()) + 1000000;
  if (s.core->GetCycle(unknown).status().code() != absl::StatusCode::kNotFound ||
      s.core->CancelCycle(unknown).code() != absl::StatusCode::kNotFound ||
      s.core->WatchCycle(unknown, [](const StoredEvent&) { return true; }).code() !=
          absl::StatusCode::kNotFound) {
    return Violation("an unknown cycle id is not NOT_FOUND everywhere");
  }
  absl::StatusOr<StoredCycle> c = RunOneCycle(s, [&](std::int64_t id) {
    const absl::StatusOr<std::int64_t> second = s.core->StartCycle(s.request);
    if (second.ok()) s.started.push_back(*second);
    if (second.status().code() != absl::StatusCode::kFailedPrecondition) {
      return Violation(
          absl::StrCat("a second StartCycle while ", id, " runs: ", second.status().ToString()));
    }
    return absl::OkStatus();
  });
  if (!c.ok()) return c.status();
  if (absl::Status st = ExpectClean(s, *c); !st.ok()) return st;
  CycleFilter newest;
  newest.page_size = 1;
  absl::StatusOr<CyclePage> page = s.core->ListCycles(newest);
  if (!page.ok() || page->cycles.empty() || page->cycles[0].id != c->id) {
    return Violation("refused requests left cycles in the store");
  }
  return std::string(
      "9 refused INVALID_ARGUMENT, NOT_FOUND, busy FAILED_PRECONDITION, then done as cycle 0");
}

// A core of its own on `data_root` (the pristine capture copied in as its replay capture,
// its database inside), for the faults that break the storage under it: the soak's core and
// database stay whole. Its expected errors are not logged.
absl::StatusOr<std::unique_ptr<StationCore>> ScratchCore(const Soak& s, const fs::path& data_root) {
  std::error_code ec;
  fs::create_directories(data_root, ec);
  if (!ec) fs::copy(s.pristine, data_root / "replay", fs::copy_options::recursive, ec);
  if (ec) return Violation(absl::StrCat("scratch core: ", data_root.string(), ": ", ec.message()));
  StationCoreConfig config = s.config;
  config.data_root = data_root.string();
  config.db_path = (data_root / "station.db").string();
  config.log = [](const LogRecord&) {};
  absl::StatusOr<std::unique_ptr<StationCore>> core = StationCore::Create(config);
  if (!core.ok()) return Violation(absl::StrCat("scratch core: ", core.status().ToString()));
  return core;
}

// After a storage fault: the cycle ended (not running), either with `reason_prefix` or, when
// the fault came after its end, as cycle 0 ended. True when it met the fault.
absl::StatusOr<bool> ExpectEndedByFault(const Soak& s, const StoredCycle& c,
                                        const std::string& reason_prefix) {
  if (absl::Status st = ExpectEnded(c); !st.ok()) return st;
  if (c.reason.rfind(reason_prefix, 0) == 0 && c.verdict == Verdict::kError) return true;
  if (c.state == CycleState::kDone && c.verdict == s.clean.verdict && c.reason == s.clean.reason) {
    return false;
  }
  return Violation(absl::StrCat("cycle ", c.id, ": ", CycleStateName(c.state), " ",
                                VerdictName(c.verdict), " '", c.reason, "', expected error ",
                                reason_prefix, "... or cycle 0's end"));
}

// Issue 21, item 7: the data root (database included) deleted at a random moment of a cycle.
absl::StatusOr<std::string> DataRootDeleted(Soak& s) {
  const fs::path root = s.dir / "deleted_root";
  fs::remove_all(root);
  absl::StatusOr<std::unique_ptr<StationCore>> core = ScratchCore(s, root);
  if (!core.ok()) return core.status();
  const absl::StatusOr<std::int64_t> id = (*core)->StartCycle(s.request);
  if (!id.ok()) return Violation(absl::StrCat("StartCycle: ", id.status().ToString()));
  // A random moment from the start to a clean cycle's end.
  std::this_thread::sleep_for(
      std::chrono::duration_cast<Clock::duration>(s.clean_time * Uniform(s, 0, 1)));
  std::error_code ec;
  fs::remove_all(root, ec);  // nothing writes into it during a replay cycle
  if (ec) return Violation(absl::StrCat("remove ", root.string(), ": ", ec.message()));
  (*core)->WaitIdle();
  absl::StatusOr<StoredCycle> c = (*core)->GetCycle(*id);
  if (!c.ok()) return Violation(absl::StrCat("GetCycle: ", c.status().ToString()));
  absl::StatusOr<bool> met = ExpectEndedByFault(s, *c, "data_root_removed: ");
  if (!met.ok()) return met.status();
  const absl::Status health = (*core)->Health();
  const absl::Status next = (*core)->StartCycle(s.request).status();
  if (!absl::IsFailedPrecondition(health) || !absl::IsFailedPrecondition(next)) {
    return Violation(absl::StrCat("data root gone: health ", health.ToString(), ", StartCycle ",
                                  next.ToString(), ", expected FAILED_PRECONDITION for both"));
  }
  core->reset();
  return std::string(*met ? "error data_root_removed, NOT_SERVING, next start refused"
                          : "ended before the deletion; NOT_SERVING, next start refused");
}

// Issue 21, item 1: a tmpfs holding the data root and the database filled to the last byte at
// a random moment of a cycle; then the space freed. Needs root (to mount); else skipped.
absl::StatusOr<std::string> DiskFull(Soak& s) {
  if (::geteuid() != 0) return std::string("skipped: mounting a tmpfs needs root");
  const fs::path mount = s.dir / "full";
  fs::create_directories(mount);
  std::uintmax_t capture_bytes = 0;
  for (const fs::directory_entry& e : fs::recursive_directory_iterator(s.pristine)) {
    if (e.is_regular_file()) capture_bytes += e.file_size();
  }
  // The capture, the database and kFreeBytesToServe with room to spare once the filler goes.
  const std::string options = absl::StrCat("size=", capture_bytes + (24u << 20));
  if (::mount("tmpfs", mount.c_str(), "tmpfs", 0, options.c_str()) != 0) {
    return std::string("skipped: mount -t tmpfs: ") + std::strerror(errno);
  }
  struct Unmount {
    fs::path at;
    ~Unmount() { ::umount2(at.c_str(), MNT_DETACH); }
  } unmount{mount};
  absl::StatusOr<std::unique_ptr<StationCore>> core = ScratchCore(s, mount / "data");
  if (!core.ok()) return core.status();
  StationCore& full = **core;
  const absl::StatusOr<std::int64_t> id = full.StartCycle(s.request);
  if (!id.ok()) return Violation(absl::StrCat("StartCycle: ", id.status().ToString()));
  // A random moment from the start to a clean cycle's end.
  std::this_thread::sleep_for(
      std::chrono::duration_cast<Clock::duration>(s.clean_time * Uniform(s, 0, 1)));
  const fs::path filler = mount / "filler";
  FillFileSystem(filler.string());
  full.WaitIdle();
  absl::StatusOr<StoredCycle> c = full.GetCycle(*id);
  if (!c.ok()) return Violation(absl::StrCat("GetCycle: ", c.status().ToString()));
  absl::StatusOr<bool> met = ExpectEndedByFault(s, *c, "disk_full: ");
  if (!met.ok()) return met.status();
  // The disk is full: a new cycle is refused (or, if SQLite found room, ends like any).
  const absl::StatusOr<std::int64_t> next = full.StartCycle(s.request);
  if (next.ok()) {
    full.WaitIdle();
    absl::StatusOr<StoredCycle> n = full.GetCycle(*next);
    if (!n.ok()) return Violation(absl::StrCat("GetCycle: ", n.status().ToString()));
    absl::StatusOr<bool> m = ExpectEndedByFault(s, *n, "disk_full: ");
    if (!m.ok()) return m.status();
  } else if (!absl::IsResourceExhausted(next.status())) {
    return Violation(absl::StrCat("StartCycle on a full disk: ", next.status().ToString(),
                                  ", expected RESOURCE_EXHAUSTED"));
  }
  if ((*met || !next.ok()) && full.Health().ok()) {
    return Violation("a full disk, yet Health() is OK");
  }
  fs::remove(filler);
  if (const absl::Status h = full.Health(); !h.ok()) {
    return Violation(absl::StrCat("space back, yet Health(): ", h.ToString()));
  }
  absl::StatusOr<StoredCycle> stored = full.store().GetCycle(*id);
  if (!stored.ok() || stored->state == CycleState::kRunning || stored->reason != c->reason) {
    return Violation(absl::StrCat("cycle ", *id, "'s end not stored once space returned"));
  }
  absl::StatusOr<std::int64_t> after = full.StartCycle(s.request);
  if (!after.ok()) {
    return Violation(absl::StrCat("StartCycle once space returned: ", after.status().ToString()));
  }
  full.WaitIdle();
  absl::StatusOr<StoredCycle> a = full.GetCycle(*after);
  if (!a.ok() || a->state != CycleState::kDone || a->verdict != s.clean.verdict) {
    return Violation(absl::StrCat("the cycle after the space returned did not end as cycle 0"));
  }
  if (const absl::Status integrity = full.store().IntegrityCheck(); !integrity.ok()) {
    return Violation(absl::StrCat("integrity_check after the full disk: ", integrity.ToString()));
  }
  core->reset();
  return std::string(*met ? "error disk_full, NOT_SERVING, stored and serving once space returned"
                          : "ended before the disk filled; refused, serving once space returned");
}

// Issue 21, item 2: the process's descriptors run out at a random moment of a cycle, for a
// random while up to a clean cycle's time: the soft RLIMIT_NOFILE is lowered to the lowest
// free descriptor (every open, socket or pipe then fails with EMFILE), then restored. The
// cycle must end stored, as cycle 0 or in error with a reason; the descriptors it opened are
// closed again (the final check counts them); the station is healthy and the next cycle is as
// cycle 0. (linecald's gRPC listener under the same fault: the crash test and
// LinecaldProcessTest.AcceptsAgainAfterDescriptorsRanOut.)
absl::StatusOr<std::string> DescriptorsExhausted(Soak& s) {
  rlimit before{};
  if (::getrlimit(RLIMIT_NOFILE, &before) != 0) {
    return Violation(absl::StrCat("getrlimit: ", std::strerror(errno)));
  }
  bool exhausted = false;
  absl::StatusOr<StoredCycle> c = RunOneCycle(s, [&](std::int64_t) {
    std::this_thread::sleep_for(
        std::chrono::duration_cast<Clock::duration>(s.clean_time * Uniform(s, 0, 1)));
    const int lowest_free = ::open("/dev/null", O_RDONLY | O_CLOEXEC);
    if (lowest_free < 0) return Violation("no descriptor free before the fault");
    ::close(lowest_free);
    rlimit limit = before;
    limit.rlim_cur = static_cast<rlim_t>(lowest_free);
    if (::setrlimit(RLIMIT_NOFILE, &limit) != 0) {
      return Violation(absl::StrCat("setrlimit: ", std::strerror(errno)));
    }
    const int more = ::open("/dev/null", O_RDONLY | O_CLOEXEC);
    exhausted = more < 0 && errno == EMFILE;
    if (more >= 0) ::close(more);
    std::this_thread::sleep_for(
        std::chrono::duration_cast<Clock::duration>(s.clean_time * Uniform(s, 0, 1)));
    if (::setrlimit(RLIMIT_NOFILE, &before) != 0) {
      return Violation(absl::StrCat("setrlimit (restore): ", std::strerror(errno)));
    }
    return exhausted ? absl::OkStatus()
                     : Violation("descriptors not exhausted by the lowered limit");
  });
  ::setrlimit(RLIMIT_NOFILE, &before);  // whatever happened above
  if (!c.ok()) return c.status();
  if (absl::Status st = ExpectEnded(*c); !st.ok()) return st;
  std::string outcome;
  if (ExpectClean(s, *c).ok()) {
    outcome = "done as cycle 0";
  } else if (c->verdict == Verdict::kError) {
    // The kind of error, without the file names: "sensor error data_unreadable", ...
    outcome =
        absl::StrCat(CycleStateName(c->state), " error ", c->reason.substr(0, c->reason.find(':')));
    for (const StoredSensorResult& r : c->sensors) {
      if (r.verdict == Verdict::kError) {
        outcome = absl::StrCat(CycleStateName(c->state), " error, a sensor ", r.reason);
        break;
      }
    }
  } else {
    return Violation(absl::StrCat(
        "cycle ", c->id, " with descriptors exhausted: ", CycleStateName(c->state), " ",
        VerdictName(c->verdict), " '", c->reason, "', expected cycle 0's end or an error"));
  }
  if (const absl::Status h = s.core->Health(); !h.ok()) {
    return Violation(absl::StrCat("descriptors back, yet Health(): ", h.ToString()));
  }
  absl::StatusOr<StoredCycle> next = RunOneCycle(s);
  if (!next.ok()) return next.status();
  if (absl::Status st = ExpectClean(s, *next); !st.ok()) return st;
  return absl::StrCat(outcome, "; the next cycle as cycle 0");
}

// ---- Live sources (soak_live.h) ----

// The live core's request: the soak's, for the car of its LiDARs and radars.
CycleRequest LiveRequest(const Soak& s) {
  CycleRequest r = s.request;
  r.car_model_id = LiveRig::kCarId;
  return r;
}

// The reference of every undisturbed live sensor: the first clean live cycle, made on first use
// and required to end with every sensor acquired (its verdict may be an error of the
// calibration, as cycle 0's may: the soak's car is a random one).
absl::StatusOr<const LiveCycle*> LiveReference(Soak& s) {
  if (s.live_clean) return &*s.live_clean;
  absl::StatusOr<LiveCycle> c = s.live.Run(LiveRequest(s), {});
  if (!c.ok()) return c.status();
  if (absl::Status st = ExpectEnded(c->stored); !st.ok()) return st;
  for (const StoredSensorResult& r : c->stored.sensors) {
    if (r.reason.rfind("acquisition_failed", 0) == 0) {
      return Violation(absl::StrCat("clean live cycle: ", r.sensor, " '", r.reason, "'"));
    }
  }
  s.live_clean = *std::move(c);
  return &*s.live_clean;
}

double ToSeconds(Clock::duration d) { return std::chrono::duration<double>(d).count(); }

// The live cycle ended done within the acquisition deadline and twice the clean live cycle,
// every sensor but `faulted` as in the clean live cycle, `faulted` with a verdict, or an error
// with a reason that the cycle's reason carries. Returns `faulted`'s outcome for the summary:
// its verdict, " as clean" when its result is the clean one's, and the reason's code
// ("error acquisition_failed"); with `faulted` empty, every sensor as in the clean live cycle.
absl::StatusOr<std::string> ExpectLiveFaulted(const LiveCycle& clean, const LiveCycle& c,
                                              const std::string& faulted) {
  const StoredCycle& got = c.stored;
  if (absl::Status st = ExpectEnded(got); !st.ok()) return st;
  if (got.state != CycleState::kDone || got.sensors.size() != clean.stored.sensors.size()) {
    return Violation(absl::StrCat("live cycle: ", CycleStateName(got.state), " with ",
                                  got.sensors.size(), " sensors (", got.reason, ")"));
  }
  const Clock::duration bound = 2 * clean.wall + LiveRig::kAcquireDeadline;
  if (c.wall > bound) {
    return Violation(absl::StrFormat("live cycle took %.1f s, over %.1f s", ToSeconds(c.wall),
                                     ToSeconds(bound)));
  }
  std::string outcome;
  for (size_t i = 0; i < got.sensors.size(); ++i) {
    const StoredSensorResult& r = got.sensors[i];
    if (r.sensor != faulted) {
      if (!(r == clean.stored.sensors[i]))
        return Violation(absl::StrCat("live cycle: ", r.sensor, " differs from the clean one"));
      continue;
    }
    outcome = VerdictName(r.verdict);
    if (r == clean.stored.sensors[i]) outcome += " as clean";
    if (r.verdict != Verdict::kError) continue;
    if (r.reason.empty() || got.reason.find(faulted + ":") == std::string::npos) {
      return Violation(absl::StrCat("live cycle: ", faulted, " error '", r.reason,
                                    "', cycle reason '", got.reason, "'"));
    }
    outcome += " " + r.reason.substr(0, r.reason.find(':'));
  }
  if (faulted.empty()) return std::string("done as the clean live cycle");
  if (outcome.empty()) return Violation(absl::StrCat("live cycle: no result for ", faulted));
  return outcome;
}

// One of the car's LiDARs, its packets sent with `send`; the cycle must end as
// ExpectLiveFaulted says.
absl::StatusOr<std::string> LiveLidarFault(Soak& s, const testing_daemon::SendFaults& send,
                                           std::string* lidar) {
  absl::StatusOr<const LiveCycle*> clean = LiveReference(s);
  if (!clean.ok()) return clean.status();
  *lidar = s.live.lidars()[Pick(s, s.live.lidars().size())];
  absl::StatusOr<LiveCycle> c = s.live.Run(LiveRequest(s), {*lidar, send, ""});
  if (!c.ok()) return c.status();
  return ExpectLiveFaulted(**clean, *c, *lidar);
}

absl::StatusOr<std::string> LiveClean(Soak& s) {
  if (s.live.empty()) return std::string("skipped: the car has no LiDAR or radar");
  absl::StatusOr<const LiveCycle*> clean = LiveReference(s);
  if (!clean.ok()) return clean.status();
  absl::StatusOr<LiveCycle> c = s.live.Run(LiveRequest(s), {});
  if (!c.ok()) return c.status();
  if (c->stored.verdict != (*clean)->stored.verdict || c->stored.reason != (*clean)->stored.reason)
    return Violation(absl::StrCat("live cycle: '", c->stored.reason, "', the clean one had '",
                                  (*clean)->stored.reason, "'"));
  return ExpectLiveFaulted(**clean, *c, "");
}

// One LiDAR's packets each lost (or cut short) with a probability drawn in [lo, hi].
absl::StatusOr<std::string> LidarPacketsDamaged(Soak& s, double testing_daemon::SendFaults::*rate,
                                                double lo, double hi) {
  if (s.live.lidars().empty()) return std::string("skipped: the car has no LiDAR");
  testing_daemon::SendFaults send;
  send.*rate = Uniform(s, lo, hi);
  send.seed = s.rng();
  std::string lidar;
  return LiveLidarFault(s, send, &lidar);
}
absl::StatusOr<std::string> LidarPacketLoss(Soak& s) {
  return LidarPacketsDamaged(s, &testing_daemon::SendFaults::lose, 0.02, 0.5);
}
absl::StatusOr<std::string> LidarPacketsCut(Soak& s) {
  return LidarPacketsDamaged(s, &testing_daemon::SendFaults::cut, 0.01, 0.3);
}

// The LiDAR sends nothing (a third of the draws) or falls silent after up to 1.5 recordings'
// worth of packets; silent from the start, it must be given up at the deadline by name.
absl::StatusOr<std::string> LidarVanishes(Soak& s) {
  if (s.live.lidars().empty()) return std::string("skipped: the car has no LiDAR");
  const std::string& first = s.live.lidars().front();
  testing_daemon::SendFaults send;
  send.stop_after = Pick(s, 3) == 0 ? 0 : 1 + Pick(s, s.live.PacketCount(first) * 3 / 2);
  std::string lidar;
  absl::StatusOr<std::string> outcome = LiveLidarFault(s, send, &lidar);
  if (!outcome.ok() || *send.stop_after != 0) return outcome;
  if (*outcome != "error acquisition_failed")
    return Violation(absl::StrCat("a LiDAR that never sent: ", lidar, " ", *outcome));
  return absl::StrCat(*outcome, " (never sent)");
}

// A radar's bus silent: its candump log empty. It must be that radar's acquisition_failed,
// saying the radar was silent, the other sensors as in the clean live cycle.
absl::StatusOr<std::string> RadarSilent(Soak& s) {
  if (s.live.radars().empty()) return std::string("skipped: the car has no radar");
  absl::StatusOr<const LiveCycle*> clean = LiveReference(s);
  if (!clean.ok()) return clean.status();
  const std::string radar = s.live.radars()[Pick(s, s.live.radars().size())];
  absl::StatusOr<LiveCycle> c = s.live.Run(LiveRequest(s), {"", {}, radar});
  if (!c.ok()) return c.status();
  absl::StatusOr<std::string> outcome = ExpectLiveFaulted(**clean, *c, radar);
  if (!outcome.ok()) return outcome;
  for (const StoredSensorResult& r : c->stored.sensors) {
    if (r.sensor == radar && r.message.find("the radar was silent") == std::string::npos)
      return Violation(absl::StrCat("silent radar ", radar, ": '", r.message, "'"));
  }
  if (*outcome != "error acquisition_failed")
    return Violation(absl::StrCat("silent radar ", radar, ": ", *outcome));
  return *outcome;
}

std::vector<Fault> Faults() {
  return {
      {"clean", 30, "no fault: the result must equal cycle 0's", Clean},
      {"corrupt_camera_frame", 8, "32 random bytes in the second half of a camera's PNG",
       CorruptCameraFrame},
      {"truncated_camera_frame", 8, "a camera's PNG cut to 10-90% of its length",
       TruncatedCameraFrame},
      {"truncated_lidar_scan", 8, "a LiDAR's PCD scan cut to 30-95% of its length",
       TruncatedLidarScan},
      {"truncated_can_log", 8, "a radar's candump log cut inside a line's time stamp",
       TruncatedCanLog},
      {"missing_file", 6, "one file of the capture (manifest, station, car or sensor data) deleted",
       MissingFile},
      {"db_locked_briefly", 6,
       "another connection holds the write lock for a third of the busy timeout",
       DatabaseLockedBriefly},
      {"db_locked_at_start", 4,
       "the write lock held by another connection when the cycle is started",
       DatabaseLockedAtStart},
      {"db_locked_mid_cycle", 3,
       "the write lock held from the start for two cycles and 4 busy timeouts",
       DatabaseLockedMidCycle},
      {"cancel", 12, "CancelCycle at a random moment from the start to 1.2 clean cycles",
       CancelAtRandom},
      {"invalid_requests", 7,
       "9 invalid requests, unknown ids, a second start while running; then a cycle",
       InvalidRequests},
      {"disk_full", 2, "a tmpfs under the data root and database filled during a cycle, freed",
       DiskFull},
      {"data_root_deleted", 2, "the data root with the database deleted during a cycle",
       DataRootDeleted},
      {"descriptors_exhausted", 2,
       "RLIMIT_NOFILE lowered to the descriptors open during a cycle, restored; then a cycle",
       DescriptorsExhausted},
      {"live_clean", 3, "live sources (LiDARs over loopback UDP, radars from CAN logs), no fault",
       LiveClean},
      {"lidar_packet_loss", 4, "live: 2-50% of one LiDAR's UDP packets lost", LidarPacketLoss},
      {"lidar_packets_cut", 3, "live: 1-30% of one LiDAR's UDP packets cut short", LidarPacketsCut},
      {"lidar_vanishes", 3, "live: one LiDAR silent from the start or after some packets",
       LidarVanishes},
      {"radar_silent", 3, "live: one radar's CAN bus silent", RadarSilent},
  };
}

double Mb(std::int64_t kb) { return kb / 1024.0; }

// Memory is sampled every this many cycles after the warm-up: 91 samples in 1,000 cycles,
// each a read of /proc/self/status and mallinfo2.
constexpr int kMemorySampleEvery = 10;
// A line through fewer samples says nothing: a run shorter than the warm-up plus 100 cycles
// is not judged (the smoke's 20 cycles).
constexpr size_t kMinMemorySamples = 10;

// Bytes malloc has handed out and not got back, every arena (glibc's mallinfo2).
std::size_t HeapInUseBytes() {
  const struct mallinfo2 m = mallinfo2();
  return m.uordblks + m.hblkhd;
}

// What a soak run gathers, for the final checks and the report.
struct SoakTally {
  std::map<std::string, std::map<std::string, int>> outcomes;  // fault -> outcome -> cycles
  std::vector<std::string> violations;
  int threads_before = 0, fds_before = 0;      // before cycle 0
  int threads_baseline = 0, fds_baseline = 0;  // after cycle 0
  int threads_end = 0, fds_end = 0;
  // Memory after the warm-up (cycle rss_from), every kMemorySampleEvery cycles and at the end:
  // the cycle number, the resident set and the heap in use, MB.
  std::vector<double> memory_cycles, rss_mb, heap_mb;
  double wall_s = 0;
  int ended = 0, stored = 0;  // started cycles ended with a reason; cycles in the store
  absl::Status integrity;
  bool memory_checked = false;
  MemoryGrowth rss_growth, heap_growth;
  double rss_bound_mb = 0;
};

// The soak's scratch copy of the capture, the replaying core (returned; `s` points to it) and
// the cycle request, in `s`. The error is the setup's.
absl::StatusOr<std::unique_ptr<StationCore>> SetUpSoak(const Workspace& workspace,
                                                       const ProgramFlags& flags, Soak* s) {
  const fs::path dir = workspace.dir;
  s->dir = dir;
  s->rng.seed(flags.seed);
  s->pristine = dir / "pristine";
  s->capture = dir / "data" / "replay";
  s->db_path = (dir / "soak.db").string();
  fs::copy(s->pristine, s->capture, fs::copy_options::recursive);
  absl::StatusOr<Capture> layout = ReadCapture(s->pristine.string());
  if (!layout.ok()) return layout.status();
  s->layout = *std::move(layout);

  StationCoreConfig config;
  config.station_id = "soak";
  config.station_path = ReferenceStationPath();
  config.car_model_paths = {workspace.car_path};
  config.db_path = s->db_path;
  config.data_root = (dir / "data").string();
  config.source = CycleSource::kReplay;
  config.replay_capture = "replay";
  config.busy_timeout = kBusyTimeout;
  s->config = config;
  absl::StatusOr<std::unique_ptr<StationCore>> core = StationCore::Create(config);
  if (!core.ok()) return core.status();
  s->core = core->get();
  s->request.vin = kVin;
  s->request.car_model_id = kCarId;
  absl::StatusOr<LiveRig> live =
      LiveRig::Create(dir, s->pristine, s->layout, workspace.car_path, config);
  if (!live.ok()) return live.status();
  s->live = *std::move(live);
  return core;
}

// Runs flags.cycles cycles: cycle 0 clean (the reference), then each fault once, then faults
// drawn by weight; restores the capture after each and tallies outcomes, violations, threads,
// descriptors and memory samples in `t`, with a progress line every 50 cycles. The error is a
// setup failure (cycle 0 not done, a capture not restored).
absl::Status RunCycles(Soak& s, const std::vector<Fault>& faults, const ProgramFlags& flags,
                       int rss_from, SoakTally* t) {
  std::vector<int> weights;
  for (const Fault& f : faults) weights.push_back(f.weight);
  std::discrete_distribution<size_t> draw(weights.begin(), weights.end());
  const Clock::time_point start = Clock::now();
  for (int cycle = 0; cycle < flags.cycles; ++cycle) {
    const Fault& fault = cycle == 0                                 ? faults[0]
                         : cycle <= static_cast<int>(faults.size()) ? faults[cycle - 1]
                                                                    : faults[draw(s.rng)];
    absl::StatusOr<std::string> outcome;
    if (cycle == 0) {
      const Clock::time_point t0 = Clock::now();
      absl::StatusOr<StoredCycle> c = RunOneCycle(s);
      s.clean_time = Clock::now() - t0;
      if (!c.ok()) return c.status();
      if (c->state != CycleState::kDone) return Violation("cycle 0 did not end done: " + c->reason);
      s.clean = *std::move(c);
      outcome = std::string("done (the reference)");
    } else {
      outcome = fault.run(s);
    }
    if (absl::Status st = Restore(s); !st.ok()) return st;
    if (outcome.ok()) {
      ++t->outcomes[fault.name][*outcome];
    } else {
      ++t->outcomes[fault.name]["VIOLATION"];
      t->violations.push_back(
          absl::StrCat("cycle ", cycle, " (", fault.name, "): ", outcome.status().message()));
      std::fprintf(stderr, "linecal-soak: %s\n", t->violations.back().c_str());
    }
    if (cycle == 0) {
      // After the first cycle: one-time allocations (thread pools, caches) are made by now.
      t->threads_baseline = SettledEntryCount("/proc/self/task");
      t->fds_baseline = SettledEntryCount("/proc/self/fd");
    }
    if (cycle + 1 >= rss_from &&
        ((cycle + 1 - rss_from) % kMemorySampleEvery == 0 || cycle + 1 == flags.cycles)) {
      t->memory_cycles.push_back(cycle + 1);
      t->rss_mb.push_back(Mb(ReadProcessStatus().value_or(ProcessStatus{}).rss_kb));
      t->heap_mb.push_back(HeapInUseBytes() / 1048576.0);
    }
    if ((cycle + 1) % 50 == 0 || cycle + 1 == flags.cycles) {
      const ProcessStatus p = ReadProcessStatus().value_or(ProcessStatus{});
      std::printf("  cycle %4d  %7.1f s  rss %.1f MB  threads %d  violations %zu\n", cycle + 1,
                  std::chrono::duration<double>(Clock::now() - start).count(), Mb(p.rss_kb),
                  p.threads, t->violations.size());
      std::fflush(stdout);
    }
  }
  t->wall_s = std::chrono::duration<double>(Clock::now() - start).count();
  return absl::OkStatus();
}

// The final checks into `t`: every started cycle is stored, ended, with a reason, and nothing
// else is stored; the database's integrity; threads and descriptors back to their count after
// cycle 0.
void CheckStoreAndProcess(Soak& s, SoakTally* t) {
  for (const std::int64_t id : s.started) {
    absl::StatusOr<StoredCycle> c = s.core->GetCycle(id);
    absl::Status st = c.ok() ? ExpectEnded(*c) : c.status();
    if (st.ok()) {
      ++t->ended;
    } else {
      t->violations.push_back(absl::StrCat("final check: cycle ", id, ": ", st.message()));
    }
  }
  CycleFilter all;
  all.page_size = 1000;
  do {
    absl::StatusOr<CyclePage> page = s.core->ListCycles(all);
    if (!page.ok()) {
      t->violations.push_back(absl::StrCat("ListCycles: ", page.status().ToString()));
      break;
    }
    t->stored += static_cast<int>(page->cycles.size());
    all.page_token = page->next_page_token;
  } while (!all.page_token.empty());
  if (t->stored != static_cast<int>(s.started.size())) {
    t->violations.push_back(
        absl::StrCat(t->stored, " cycles stored, ", s.started.size(), " started"));
  }
  t->integrity = s.core->store().IntegrityCheck();
  if (!t->integrity.ok())
    t->violations.push_back(absl::StrCat("integrity_check: ", t->integrity.ToString()));
  t->threads_end = SettledEntryCount("/proc/self/task");
  t->fds_end = SettledEntryCount("/proc/self/fd");
  if (t->threads_end != t->threads_baseline) {
    t->violations.push_back(absl::StrCat("threads: ", t->threads_baseline, " after cycle 0, ",
                                         t->threads_end, " at the end"));
  }
  if (t->fds_end != t->fds_baseline) {
    t->violations.push_back(absl::StrCat("descriptors: ", t->fds_baseline, " after cycle 0, ",
                                         t->fds_end, " at the end"));
  }
}

// A least-squares line through every sample after the warm-up, for the resident set and the
// heap in use, against the bounds of reliability_support.h (kSoak*): a leak is a line that
// rises past its bound per 1,000 cycles, its slope kSoakMinSignificance standard errors
// (from the scatter about it and its autocorrelation) above 0. Not judged with fewer than
// kMinMemorySamples samples.
void JudgeMemory(int rss_from, SoakTally* t) {
  t->memory_checked = t->memory_cycles.size() >= kMinMemorySamples;
  if (!t->memory_checked) return;
  const LinearTrend line = FitLinearTrend(t->memory_cycles, t->rss_mb);
  t->rss_bound_mb = kSoakRssGrowthFractionPer1000 * (line.intercept + line.slope * rss_from);
  t->rss_growth =
      JudgeMemoryGrowth(t->memory_cycles, t->rss_mb, t->rss_bound_mb, kSoakMinSignificance);
  t->heap_growth = JudgeMemoryGrowth(t->memory_cycles, t->heap_mb, kSoakHeapGrowthMbPer1000,
                                     kSoakMinSignificance);
  for (const auto& [name, g, bound] :
       {std::tuple{"RSS", t->rss_growth, t->rss_bound_mb},
        std::tuple{"heap in use", t->heap_growth, kSoakHeapGrowthMbPer1000}}) {
    if (!g.leak) continue;
    t->violations.push_back(absl::StrFormat(
        "%s grows %.2f MB per 1000 cycles (bound %.2f MB), %.2f MB over the run, %.1f standard "
        "errors above 0 (scatter %.2f MB)",
        name, g.growth_per_1000, bound, g.run_growth, g.significance, g.trend.scatter));
  }
}

// The report on stdout: outcomes per fault, cycle times, the store's and the process's counts,
// the memory trend and every violation.
void PrintReport(const Soak& s, const std::vector<Fault>& faults, const ProgramFlags& flags,
                 int rss_from, const SoakTally& t) {
  std::vector<Clock::duration> times = s.cycle_times;
  std::sort(times.begin(), times.end());
  const auto ms = [](Clock::duration d) {
    return std::chrono::duration<double, std::milli>(d).count();
  };
  std::printf("\nfaults (cycles, outcome):\n");
  for (const Fault& f : faults) {
    const auto outcomes = t.outcomes.find(f.name);
    if (outcomes == t.outcomes.end()) continue;
    for (const auto& [what, n] : outcomes->second)
      std::printf("  %-24s %5d  %s\n", f.name.c_str(), n, what.c_str());
  }
  std::printf(
      "\n%d cycles in %.1f s; cycle wall time median %.0f ms, p95 %.0f ms, max %.0f ms (clean: "
      "%.0f ms)\n",
      flags.cycles, t.wall_s, ms(times[times.size() / 2]), ms(times[times.size() * 95 / 100]),
      ms(times.back()), ms(s.clean_time));
  std::printf("started %zu, stored %d, ended with state and reason %d\n", s.started.size(),
              t.stored, t.ended);
  std::printf("integrity_check: %s\n",
              t.integrity.ok() ? "ok" : std::string(t.integrity.message()).c_str());
  std::printf("threads: %d before cycle 0, %d after it, %d at the end\n", t.threads_before,
              t.threads_baseline, t.threads_end);
  std::printf("descriptors: %d before cycle 0, %d after it, %d at the end\n", t.fds_before,
              t.fds_baseline, t.fds_end);
  const ProcessStatus end = ReadProcessStatus().value_or(ProcessStatus{});
  if (t.memory_checked) {
    // Allocated and not freed (heap in use), against what the allocator holds (RSS): a leak
    // grows the first.
    const auto [rss_min, rss_max] = std::minmax_element(t.rss_mb.begin(), t.rss_mb.end());
    const auto [heap_min, heap_max] = std::minmax_element(t.heap_mb.begin(), t.heap_mb.end());
    std::printf(
        "memory trend over %zu samples, cycles %d-%d (least squares, MB = intercept + slope x "
        "cycle):\n",
        t.memory_cycles.size(), rss_from, flags.cycles);
    for (const auto& [name, g, bound, lo, hi] :
         {std::tuple{"RSS", t.rss_growth, t.rss_bound_mb, *rss_min, *rss_max},
          std::tuple{"heap in use", t.heap_growth, kSoakHeapGrowthMbPer1000, *heap_min,
                     *heap_max}}) {
      std::printf(
          "  %-11s slope %+.5f MB/cycle = %+.2f MB per 1000 cycles (bound %.2f), intercept %.2f "
          "MB, "
          "scatter %.2f MB, autocorrelation %.2f, slope %+.1f standard errors (leak above %.0f), "
          "rise over the run %+.2f MB, range %.1f-%.1f MB: %s\n",
          name, g.trend.slope, g.growth_per_1000, bound, g.trend.intercept, g.trend.scatter,
          g.trend.autocorrelation, g.significance, kSoakMinSignificance, g.run_growth, lo, hi,
          g.leak ? "LEAK" : "no leak");
    }
    std::printf("RSS at the end %.1f MB, peak %.1f MB\n", Mb(end.rss_kb), Mb(end.hwm_kb));
  } else {
    std::printf(
        "RSS: %.1f MB at the end, peak %.1f MB (growth not checked: fewer than %zu samples after "
        "cycle %d)\n",
        Mb(end.rss_kb), Mb(end.hwm_kb), kMinMemorySamples, rss_from);
  }
  std::printf("violations: %zu\n", t.violations.size());
  for (const std::string& v : t.violations) std::printf("  %s\n", v.c_str());
}

int Run(const ProgramFlags& flags, int rss_from) {
  absl::StatusOr<Workspace> workspace = PrepareWorkspace(flags, "soak", kCarId, "pristine");
  if (!workspace.ok()) {
    std::fprintf(stderr, "linecal-soak: setup: %s\n", workspace.status().ToString().c_str());
    return 2;
  }
  const fs::path dir = workspace->dir;
  const auto setup_failed = [&](const absl::Status& s) {
    std::fprintf(stderr, "linecal-soak: setup: %s\n", s.ToString().c_str());
    if (workspace->owned) fs::remove_all(dir);
    return 2;
  };
  Soak s;
  absl::StatusOr<std::unique_ptr<StationCore>> core = SetUpSoak(*workspace, flags, &s);
  if (!core.ok()) return setup_failed(core.status());

  const std::vector<Fault> faults = Faults();
  SoakTally t;
  t.threads_before = SettledEntryCount("/proc/self/task");
  t.fds_before = SettledEntryCount("/proc/self/fd");
  std::printf("linecal-soak: %d cycles, seed %llu, %zu sensors, scratch %s\n", flags.cycles,
              static_cast<unsigned long long>(flags.seed), s.layout.manifest.sensors.size(),
              dir.c_str());
  if (absl::Status st = RunCycles(s, faults, flags, rss_from, &t); !st.ok())
    return setup_failed(st);
  CheckStoreAndProcess(s, &t);
  JudgeMemory(rss_from, &t);
  PrintReport(s, faults, flags, rss_from, t);
  core->reset();
  if (workspace->owned) fs::remove_all(dir);
  return t.violations.empty() ? 0 : 1;
}

}  // namespace
}  // namespace linecal::reliability

int main(int argc, char** argv) {
  using linecal::reliability::ProgramFlags;
  if (argc == 3 && std::string(argv[1]) == "--hold-lock")
    return linecal::reliability::HoldLock(argv[2]);
  // The allocator as linecald's main sets it (daemon/linecald/main.cc): the soak's memory
  // figures are the daemon's.
  mallopt(M_ARENA_MAX, 2);
  ProgramFlags defaults;
  defaults.cycles = 1000;  // docs/acceptance.md's soak
  const absl::StatusOr<ProgramFlags> flags =
      linecal::reliability::ParseProgramFlags(argc, argv, defaults, {"--rss-from"});
  int rss_from = 100;  // memory growth is fitted from after this cycle (one-time allocations done)
  if (flags.ok() && flags->own.count("--rss-from") &&
      (!absl::SimpleAtoi(flags->own.at("--rss-from"), &rss_from) || rss_from < 1)) {
    rss_from = 0;
  }
  if (!flags.ok() || rss_from < 1) {
    std::fprintf(stderr,
                 "linecal-soak: %s\nusage: linecal-soak [--cycles N] [--seed S] [--sensors "
                 "a,b,...] [--rss-from K] "
                 "[--dir DIR]\n",
                 flags.ok() ? "--rss-from: not a positive number"
                            : std::string(flags.status().message()).c_str());
    return 2;
  }
  return linecal::reliability::Run(*flags, rss_from);
}
