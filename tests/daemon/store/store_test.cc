// The station store on real SQLite files in a scratch directory: schema and durability
// settings, round trips, error codes, paging, a locked database, and crashes of a writer
// process (kill -9) that must lose nothing it committed; the outbox for the plant database.
#include "daemon/store/store.h"

#include <gtest/gtest.h>
#include <signal.h>
#include <sqlite3.h>
#include <sys/mount.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <string>

#include "absl/strings/match.h"
#include "tests/daemon/ended_cycle.h"
#include "tests/daemon/reliability/reliability_support.h"

namespace linecal {
namespace {

namespace fs = std::filesystem;

class StoreTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("linecal_store_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    path_ = (dir_ / "station.db").string();
  }
  void TearDown() override {
    if (!mounted_.empty()) ::umount2(mounted_.c_str(), MNT_DETACH);
    fs::remove_all(dir_);
  }

  std::unique_ptr<Store> OpenOk(const StoreOptions& options = {}) {
    absl::StatusOr<std::unique_ptr<Store>> store = Store::Open(path_, options);
    EXPECT_TRUE(store.ok()) << store.status();
    return store.ok() ? std::move(*store) : nullptr;
  }

  // A second, raw connection, as another process would have.
  std::string RawQuery(const std::string& sql) {
    sqlite3* db = nullptr;
    EXPECT_EQ(sqlite3_open(path_.c_str(), &db), SQLITE_OK);
    std::string value;
    sqlite3_exec(
        db, sql.c_str(),
        [](void* out, int, char** values, char**) {
          *static_cast<std::string*>(out) = values[0] ? values[0] : "";
          return 0;
        },
        &value, nullptr);
    sqlite3_close(db);
    return value;
  }

  fs::path dir_;
  std::string path_;
  std::string mounted_;  // a tmpfs this test mounted, unmounted by TearDown
};

StoredCycle Request(const std::string& vin, int64_t started_ns) {
  StoredCycle c;
  c.vin = vin;
  c.car_model_id = "reference";
  c.started_ns = started_ns;
  c.request_json = R"({"vin":")" + vin + R"("})";
  return c;
}

StoredSensorResult CameraResult() {
  StoredSensorResult r;
  r.sensor = "front_camera";
  r.kind = SensorKind::kCamera;
  r.verdict = Verdict::kFail;
  r.reason = "yaw_out_of_tolerance";
  r.message = "yaw 0.61 deg off nominal, tolerance 0.5 deg";
  r.T_car_sensor = {0, 0, 1, 1.9, -1, 0, 0, 0.01, 0, -1, 0, 1.32, 0, 0, 0, 1};
  r.measured = {0.61, -1.02, 0.03, 1.9, 0.01, 1.32};
  r.deviation = {0.61, -0.02, 0.03, 0.001, 0.01, -0.002};
  r.sigma = {0.004, 0.003, 0.006, 0.0007, 0.0009, 0.0011};
  r.residual_rms = 0.187;
  r.features_used = 90;
  r.vanishing_point_u_px = 961.25;
  r.vanishing_point_v_px = 512.0625;
  r.ground_homography = {1.5, 0.25, -3, 0.0625, 7, 11, 1e-3, 2e-5, 1};
  r.ranging_json = R"([{"true_m":5,"measured_m":5.01}])";
  r.elapsed_ns = 412000000;
  // By board id, as the store reads them back; one seen whole and in part, one never seen.
  r.boards = {{"bumper_lidar_left", 3, 2, 1, 0.1328125}, {"front_chessboard", 3, 0, 0, {}}};
  return r;
}

TEST_F(StoreTest, NewDatabaseIsWalWithTheCurrentSchemaVersion) {
  std::unique_ptr<Store> store = OpenOk();
  ASSERT_NE(store, nullptr);
  EXPECT_EQ(RawQuery("PRAGMA journal_mode"), "wal");
  EXPECT_EQ(RawQuery("PRAGMA user_version"), std::to_string(Store::kSchemaVersion));
  EXPECT_EQ(RawQuery("SELECT count(*) FROM sqlite_master WHERE type = 'table' AND name IN "
                     "('cars', 'cycles', 'sensor_results', 'events')"),
            "4");
  EXPECT_EQ(store->aborted_at_open(), 0);
  EXPECT_TRUE(store->IntegrityCheck().ok());
}

TEST_F(StoreTest, CycleResultsAndEventsReadBackExactly) {
  std::unique_ptr<Store> store = OpenOk();
  absl::StatusOr<int64_t> id = store->BeginCycle(Request("WVWZZZ1JZXW000001", 1000));
  ASSERT_TRUE(id.ok()) << id.status();
  EXPECT_EQ(*store->RunningCycle(), std::optional<int64_t>(*id));
  for (int i = 0; i < 3; ++i) {
    absl::StatusOr<int64_t> seq = store->AppendEvent(
        {*id, 0, 1000 + i, EventType::kSensorAcquired, "front_camera", "", std::nullopt});
    ASSERT_TRUE(seq.ok()) << seq.status();
    EXPECT_EQ(*seq, i);
  }
  StoredSensorResult camera = CameraResult();
  StoredSensorResult radar;
  radar.sensor = "front_radar";
  radar.kind = SensorKind::kRadar;
  radar.verdict = Verdict::kPass;
  radar.T_car_sensor = {1, 0, 0, 3.7, 0, 1, 0, 0, 0, 0, 1, 0.5, 0, 0, 0, 1};
  ASSERT_TRUE(store->PutSensorResult(*id, camera).ok());
  ASSERT_TRUE(store->PutSensorResult(*id, radar).ok());
  ASSERT_TRUE(store->EndCycle(*id, CycleState::kDone, Verdict::kFail, "front_camera", 5000).ok());

  absl::StatusOr<StoredCycle> back = store->GetCycle(*id);
  ASSERT_TRUE(back.ok()) << back.status();
  EXPECT_EQ(back->vin, "WVWZZZ1JZXW000001");
  EXPECT_EQ(back->state, CycleState::kDone);
  EXPECT_EQ(back->verdict, Verdict::kFail);
  EXPECT_EQ(back->reason, "front_camera");
  EXPECT_EQ(back->started_ns, 1000);
  EXPECT_EQ(back->ended_ns, 5000);
  EXPECT_EQ(back->request_json, R"({"vin":"WVWZZZ1JZXW000001"})");
  ASSERT_EQ(back->sensors.size(), 2u);
  EXPECT_EQ(back->sensors[0], camera);  // every double bit-exact (%.17g and REAL columns)
  EXPECT_EQ(back->sensors[1], radar);
  EXPECT_FALSE(back->sensors[1].vanishing_point_u_px.has_value());

  absl::StatusOr<std::vector<StoredEvent>> events = store->Events(*id);
  ASSERT_TRUE(events.ok());
  ASSERT_EQ(events->size(), 3u);
  EXPECT_EQ((*events)[2].sequence, 2);
  EXPECT_EQ((*events)[2].time_ns, 1002);
  EXPECT_EQ(*store->RunningCycle(), std::nullopt);
}

// Sensor kinds cross the store as an enum; the column holds SensorKindName's word. Another
// word (a damaged or foreign file) is DataLoss naming the file, the sensor and the word.
TEST_F(StoreTest, UnknownSensorKindInTheFileIsDataLoss) {
  std::unique_ptr<Store> store = OpenOk();
  absl::StatusOr<int64_t> id = store->BeginCycle(Request("WVWZZZ1JZXW000001", 1000));
  ASSERT_TRUE(id.ok()) << id.status();
  ASSERT_TRUE(store->PutSensorResult(*id, CameraResult()).ok());
  EXPECT_EQ(RawQuery("SELECT kind FROM sensor_results"), "camera");
  RawQuery("UPDATE sensor_results SET kind = 'sonar'");
  const absl::StatusOr<StoredCycle> read = store->GetCycle(*id);
  ASSERT_FALSE(read.ok());
  EXPECT_EQ(read.status().code(), absl::StatusCode::kDataLoss) << read.status();
  const std::string message(read.status().message());
  EXPECT_TRUE(absl::StrContains(message, path_)) << message;
  EXPECT_TRUE(absl::StrContains(message, "'front_camera' of unknown kind 'sonar'")) << message;
}

TEST_F(StoreTest, ErrorCodesOfUnknownAndEndedCycles) {
  std::unique_ptr<Store> store = OpenOk();
  EXPECT_EQ(store->GetCycle(42).status().code(), absl::StatusCode::kNotFound);
  EXPECT_EQ(
      store->AppendEvent({42, 0, 1, EventType::kStarted, "", "", std::nullopt}).status().code(),
      absl::StatusCode::kNotFound);
  EXPECT_EQ(store->PutSensorResult(42, CameraResult()).code(), absl::StatusCode::kNotFound);
  EXPECT_EQ(store->EndCycle(42, CycleState::kDone, Verdict::kPass, "", 1).code(),
            absl::StatusCode::kNotFound);

  const int64_t id = *store->BeginCycle(Request("WVWZZZ1JZXW000001", 1));
  EXPECT_EQ(store->EndCycle(id, CycleState::kRunning, Verdict::kPass, "", 2).code(),
            absl::StatusCode::kInvalidArgument);
  ASSERT_TRUE(store->EndCycle(id, CycleState::kCancelled, Verdict::kError, "cancelled", 2).ok());
  const absl::Status again = store->EndCycle(id, CycleState::kDone, Verdict::kPass, "", 3);
  EXPECT_EQ(again.code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_NE(again.message().find("cancelled"), std::string::npos) << again;
  EXPECT_EQ(store->PutSensorResult(id, CameraResult()).code(),
            absl::StatusCode::kFailedPrecondition);
  EXPECT_EQ(store->GetCycle(id)->state, CycleState::kCancelled);
}

TEST_F(StoreTest, IdsIncreaseAndAreNeverReused) {
  std::unique_ptr<Store> store = OpenOk();
  const int64_t a = *store->BeginCycle(Request("WVWZZZ1JZXW000001", 1));
  const int64_t b = *store->BeginCycle(Request("WVWZZZ1JZXW000001", 2));
  EXPECT_EQ(b, a + 1);
  // Even when the newest row goes away, AUTOINCREMENT keeps its id retired.
  RawQuery("DELETE FROM cycles WHERE id = " + std::to_string(b));
  store.reset();  // one Store per database at a time (its lock)
  store = OpenOk();
  EXPECT_EQ(*store->BeginCycle(Request("WVWZZZ1JZXW000001", 3)), b + 1);
  EXPECT_EQ(RawQuery("SELECT last_cycle_id FROM cars WHERE vin = 'WVWZZZ1JZXW000001'"),
            std::to_string(b + 1));
}

TEST_F(StoreTest, ListFiltersAndPagesNewestFirstWithoutRepeats) {
  std::unique_ptr<Store> store = OpenOk();
  // 7 cycles: 3 VINs, started at t = 10, 20, ..., 70; verdicts pass, fail, error in turn.
  const Verdict verdicts[] = {Verdict::kPass, Verdict::kFail, Verdict::kError};
  const char* vins[] = {"WVWZZZ1JZXW000001", "WVWZZZ1JZXW000002", "WVWZZZ1JZXW000003"};
  for (int i = 0; i < 7; ++i) {
    const int64_t id = *store->BeginCycle(Request(vins[i % 3], 10 * (i + 1)));
    ASSERT_TRUE(store->EndCycle(id, CycleState::kDone, verdicts[i % 3], "", 10 * (i + 1) + 5).ok());
  }
  CycleFilter filter;
  filter.page_size = 3;
  std::vector<int64_t> started;
  std::set<int64_t> ids;
  int pages = 0;
  do {
    absl::StatusOr<CyclePage> page = store->ListCycles(filter);
    ASSERT_TRUE(page.ok()) << page.status();
    ++pages;
    for (const StoredCycle& c : page->cycles) {
      started.push_back(c.started_ns);
      ids.insert(c.id);
      EXPECT_TRUE(c.sensors.empty());
    }
    filter.page_token = page->next_page_token;
  } while (!filter.page_token.empty());
  EXPECT_EQ(pages, 3);
  EXPECT_EQ(started, (std::vector<int64_t>{70, 60, 50, 40, 30, 20, 10}));
  EXPECT_EQ(ids.size(), 7u);

  CycleFilter by_vin;
  by_vin.vin = vins[0];  // cycles 0, 3, 6
  EXPECT_EQ(store->ListCycles(by_vin)->cycles.size(), 3u);
  CycleFilter by_verdict;
  by_verdict.verdict = Verdict::kFail;  // cycles 1, 4
  absl::StatusOr<CyclePage> fails = store->ListCycles(by_verdict);
  ASSERT_EQ(fails->cycles.size(), 2u);
  EXPECT_EQ(fails->cycles[0].started_ns, 50);
  CycleFilter window;
  window.since_ns = 20;
  window.until_ns = 50;  // started 20, 30, 40
  EXPECT_EQ(store->ListCycles(window)->cycles.size(), 3u);

  CycleFilter bad;
  bad.page_token = "not-a-token";
  EXPECT_EQ(store->ListCycles(bad).status().code(), absl::StatusCode::kInvalidArgument);
  bad.page_token.clear();
  bad.page_size = 0;
  const absl::Status size = store->ListCycles(bad).status();
  EXPECT_EQ(size.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(size.message().find("page_size"), std::string::npos);
}

TEST_F(StoreTest, LockedDatabaseIsUnavailableAndNamesTheFile) {
  StoreOptions options;
  options.busy_timeout = std::chrono::milliseconds(100);
  std::unique_ptr<Store> store = OpenOk(options);
  sqlite3* other = nullptr;
  ASSERT_EQ(sqlite3_open(path_.c_str(), &other), SQLITE_OK);
  ASSERT_EQ(sqlite3_exec(other, "BEGIN EXCLUSIVE", nullptr, nullptr, nullptr), SQLITE_OK);
  const absl::StatusOr<int64_t> blocked = store->BeginCycle(Request("WVWZZZ1JZXW000001", 1));
  EXPECT_EQ(blocked.status().code(), absl::StatusCode::kUnavailable);
  EXPECT_NE(blocked.status().message().find(path_), std::string::npos) << blocked.status();
  ASSERT_EQ(sqlite3_exec(other, "COMMIT", nullptr, nullptr, nullptr), SQLITE_OK);
  sqlite3_close(other);
  // Nothing half-written stayed behind, and the store works again.
  EXPECT_TRUE(store->BeginCycle(Request("WVWZZZ1JZXW000001", 1)).ok());
  EXPECT_EQ(RawQuery("SELECT count(*) FROM cycles"), "1");
}

TEST_F(StoreTest, NewerSchemaAndForeignFilesAreRefused) {
  OpenOk();
  RawQuery("PRAGMA user_version = 99");
  const absl::Status newer = Store::Open(path_).status();
  EXPECT_EQ(newer.code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_NE(newer.message().find("99"), std::string::npos) << newer;
  EXPECT_EQ(RawQuery("PRAGMA user_version"), "99");  // left as it was

  const std::string junk = (dir_ / "junk.db").string();
  std::ofstream(junk) << std::string(4096, 'x');
  const absl::Status foreign = Store::Open(junk).status();
  EXPECT_EQ(foreign.code(), absl::StatusCode::kDataLoss) << foreign;
  EXPECT_NE(foreign.message().find(junk), std::string::npos);

  EXPECT_FALSE(Store::Open((dir_ / "no" / "such" / "dir.db").string()).ok());
}

// A writer process commits cycles as fast as it can and reports each committed id on a pipe;
// it is killed with SIGKILL mid-stream. Every id it reported must be there after reopening,
// the cycle it was in the middle of must come back aborted, and the file must be intact.
TEST_F(StoreTest, KillNineLosesNothingCommittedAndAbortsTheInterruptedCycle) {
  OpenOk();  // create the schema before forking
  int fds[2];
  ASSERT_EQ(::pipe(fds), 0);
  const pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    ::close(fds[0]);
    absl::StatusOr<std::unique_ptr<Store>> store = Store::Open(path_);
    if (!store.ok()) ::_exit(3);
    for (int64_t i = 0;; ++i) {
      absl::StatusOr<int64_t> id = (*store)->BeginCycle(Request("WVWZZZ1JZXW000001", i));
      if (!id.ok()) ::_exit(4);
      (*store)->AppendEvent({*id, 0, i, EventType::kStarted, "", "", std::nullopt}).IgnoreError();
      // Every second cycle ends: the other half are left running, as a crash leaves them.
      if (i % 2 == 0 && !(*store)->EndCycle(*id, CycleState::kDone, Verdict::kPass, "", i + 1).ok())
        ::_exit(5);
      if (::write(fds[1], &*id, sizeof(*id)) != sizeof(*id)) ::_exit(6);
    }
  }
  ::close(fds[1]);
  const int64_t killed_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(
                                std::chrono::system_clock::now().time_since_epoch())
                                .count();
  std::vector<int64_t> committed;
  int64_t id = 0;
  // 40 commits: enough to be mid-stream, few enough to stay quick with fsync on every commit.
  while (committed.size() < 40 && ::read(fds[0], &id, sizeof(id)) == sizeof(id))
    committed.push_back(id);
  ::kill(child, SIGKILL);
  int status = 0;
  ::waitpid(child, &status, 0);
  ::close(fds[0]);
  ASSERT_TRUE(WIFSIGNALED(status)) << "writer exited early with " << WEXITSTATUS(status);
  ASSERT_EQ(committed.size(), 40u);

  std::unique_ptr<Store> store = OpenOk();
  EXPECT_TRUE(store->IntegrityCheck().ok());
  EXPECT_GE(store->aborted_at_open(), 20);  // the odd cycles among the 40, at least
  for (int64_t c : committed) {
    absl::StatusOr<StoredCycle> cycle = store->GetCycle(c);
    ASSERT_TRUE(cycle.ok()) << "committed cycle " << c << " lost: " << cycle.status();
    if (cycle->started_ns % 2 == 0) {
      EXPECT_EQ(cycle->state, CycleState::kDone) << c;
    } else {
      EXPECT_EQ(cycle->state, CycleState::kAborted) << c;
      EXPECT_EQ(cycle->reason, "daemon_restarted");
      EXPECT_EQ(cycle->verdict, Verdict::kError);
      // Ended when the reopen found it: after the kill, not 0 ("still running").
      EXPECT_GE(cycle->ended_ns, killed_ns) << c;
    }
  }
  EXPECT_EQ(*store->RunningCycle(), std::nullopt);
}

// One Store per database: a second Open, as a second daemon on the same configuration
// would do, is refused before SQLite opens the file, naming the lock file and the holder's
// pid, and the first Store's running cycle stays running (it used to come back aborted).
TEST_F(StoreTest, SecondStoreIsRefusedNamingTheLockFileAndItsHolder) {
  std::unique_ptr<Store> store = OpenOk();
  const int64_t id = *store->BeginCycle(Request("WVWZZZ1JZXW000001", 1));
  const absl::Status second = Store::Open(path_).status();
  EXPECT_EQ(second.code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_EQ(second.message(), "database " + path_ + ": in use by another linecald (pid " +
                                  std::to_string(::getpid()) + " holds the lock file " + path_ +
                                  ".lock)");
  EXPECT_EQ(store->GetCycle(id)->state, CycleState::kRunning);
  EXPECT_TRUE(store->EndCycle(id, CycleState::kDone, Verdict::kPass, "", 2).ok());
  // Once the first is gone, the next one opens.
  store.reset();
  EXPECT_NE(OpenOk(), nullptr);
}

// Issue 21, item 1: SQLITE_FULL was an Internal error like any other, which the core did not
// retry or keep: now it is ResourceExhausted naming the database, nothing of the call is
// stored, and the same call works once space returns. A real tmpfs filled to the last byte.
TEST_F(StoreTest, FullDiskIsResourceExhaustedAndTheWriteWorksOnceSpaceReturns) {
  if (::geteuid() != 0) GTEST_SKIP() << "mounting a tmpfs needs root";
  const fs::path at = dir_ / "tmpfs";
  fs::create_directories(at);
  // 4 MiB: the database and its WAL with room to spare, filled by the test.
  ASSERT_EQ(::mount("tmpfs", at.c_str(), "tmpfs", 0, "size=4194304"), 0) << std::strerror(errno);
  mounted_ = at.string();
  path_ = (at / "station.db").string();
  std::unique_ptr<Store> store = OpenOk();
  ASSERT_NE(store, nullptr);
  const int64_t id = *store->BeginCycle(Request("WVWZZZ1JZXW000001", 1));
  ASSERT_GT(reliability::FillFileSystem((at / "filler").string()), 0u);

  const absl::StatusOr<int64_t> event =
      store->AppendEvent({id, 0, 2, EventType::kCycleEnded, "", "x", Verdict::kError});
  EXPECT_EQ(event.status().code(), absl::StatusCode::kResourceExhausted) << event.status();
  EXPECT_NE(event.status().message().find("database " + path_), std::string::npos);
  EXPECT_NE(event.status().message().find("database or disk is full"), std::string::npos);
  const absl::Status end = store->EndCycle(id, CycleState::kDone, Verdict::kError, "disk_full", 3);
  EXPECT_EQ(end.code(), absl::StatusCode::kResourceExhausted) << end;
  EXPECT_EQ(store->GetCycle(id)->state, CycleState::kRunning);  // nothing of it stored

  fs::remove(at / "filler");
  EXPECT_TRUE(
      store->AppendEvent({id, 0, 2, EventType::kCycleEnded, "", "x", Verdict::kError}).ok());
  ASSERT_TRUE(store->EndCycle(id, CycleState::kDone, Verdict::kError, "disk_full", 3).ok());
  EXPECT_EQ(store->GetCycle(id)->reason, "disk_full");
  EXPECT_EQ(store->Events(id)->size(), 1u);
  EXPECT_TRUE(store->IntegrityCheck().ok());
}

// Issue 21, item 7: a database file deleted or replaced under an open Store is still written
// through SQLite's descriptor, every call succeeding; CheckFile says so, naming the file.
TEST_F(StoreTest, CheckFileNamesARemovedOrReplacedDatabase) {
  std::unique_ptr<Store> store = OpenOk();
  ASSERT_TRUE(store->CheckFile().ok());
  fs::copy_file(path_, path_ + ".copy");
  fs::rename(path_ + ".copy", path_);  // another file (inode) under the same name
  absl::Status s = store->CheckFile();
  EXPECT_EQ(s.code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_EQ(s.message().rfind("database " + path_ + ": the file was replaced", 0), 0u) << s;
  fs::remove(path_);
  s = store->CheckFile();
  EXPECT_EQ(s.code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_EQ(s.message().rfind("database " + path_ + ": the file was removed", 0), 0u) << s;
  // Writes still "succeed": why the core must look.
  EXPECT_TRUE(store->BeginCycle(Request("WVWZZZ1JZXW000001", 1)).ok());
}

// The outbox of cycles for the plant database (docs/plant.md, "Forwarding"): queued in the
// transaction that ends a cycle, read back in order with the cycle's sensors and events,
// removed once shipped, migrated from schema 1, consistent after a writer's SIGKILL.
StoreOptions WithOutbox() {
  StoreOptions options;
  options.outbox = true;
  return options;
}

// A cycle with one sensor result and two events, ended `done` at `ended_ns`.
int64_t OutboxCycle(Store& store, int64_t started_ns, int64_t ended_ns) {
  const int64_t id = testing_daemon::EndCycleInStore(store, started_ns, ended_ns);
  EXPECT_NE(id, 0) << "the store refused the cycle";
  return id;
}

TEST_F(StoreTest, OutboxWithoutTheOptionNothingIsQueued) {
  std::unique_ptr<Store> store = OpenOk();
  OutboxCycle(*store, 1, 2);
  EXPECT_EQ(RawQuery("SELECT COUNT(*) FROM outbox"), "0");
  const absl::StatusOr<OutboxBacklog> backlog = store->Backlog();
  ASSERT_TRUE(backlog.ok()) << backlog.status();
  EXPECT_EQ(backlog->cycles, 0);
  EXPECT_EQ(backlog->oldest_ended_ns, 0);
  EXPECT_TRUE(store->ReadOutbox(10)->empty());
}

TEST_F(StoreTest, OutboxEndedCyclesAreReadInOrderWithSensorsAndEventsAndRemovedOnceShipped) {
  std::unique_ptr<Store> store = OpenOk(WithOutbox());
  std::vector<int64_t> ids;
  for (int i = 0; i < 3; ++i) ids.push_back(OutboxCycle(*store, 100 * i, 100 * i + 50));
  // A running cycle is not queued until it ends.
  StoredCycle running;
  running.vin = "WVWZZZ1JZXW000001";
  running.car_model_id = "reference";
  running.request_json = "{}";
  ASSERT_TRUE(store->BeginCycle(running).ok());

  absl::StatusOr<OutboxBacklog> backlog = store->Backlog();
  ASSERT_TRUE(backlog.ok()) << backlog.status();
  EXPECT_EQ(backlog->cycles, 3);
  EXPECT_EQ(backlog->oldest_ended_ns, 50);

  absl::StatusOr<std::vector<OutboxEntry>> first = store->ReadOutbox(2);
  ASSERT_TRUE(first.ok()) << first.status();
  ASSERT_EQ(first->size(), 2u);
  for (size_t i = 0; i < 2; ++i) {
    const OutboxEntry& e = (*first)[i];
    EXPECT_EQ(e.cycle.id, ids[i]);
    EXPECT_EQ(e.cycle.state, CycleState::kDone);
    EXPECT_EQ(e.cycle.ended_ns, 100 * static_cast<int64_t>(i) + 50);
    // Exactly what GetCycle and Events answer.
    const StoredCycle stored = *store->GetCycle(ids[i]);
    EXPECT_EQ(e.cycle.sensors, stored.sensors);
    ASSERT_EQ(e.cycle.sensors.size(), 1u);
    ASSERT_EQ(e.events.size(), 2u);
    EXPECT_EQ(e.events[0].type, EventType::kStarted);
    EXPECT_EQ(e.events[1].type, EventType::kCycleEnded);
    EXPECT_EQ(e.events[1].sequence, 1);
  }
  EXPECT_LT((*first)[0].seq, (*first)[1].seq);

  ASSERT_TRUE(store->MarkShipped((*first)[1].seq).ok());
  backlog = store->Backlog();
  EXPECT_EQ(backlog->cycles, 1);
  EXPECT_EQ(backlog->oldest_ended_ns, 250);
  absl::StatusOr<std::vector<OutboxEntry>> rest = store->ReadOutbox(100);
  ASSERT_TRUE(rest.ok()) << rest.status();
  ASSERT_EQ(rest->size(), 1u);
  EXPECT_EQ((*rest)[0].cycle.id, ids[2]);
  EXPECT_GT((*rest)[0].seq, (*first)[1].seq);

  ASSERT_TRUE(store->MarkShipped((*rest)[0].seq).ok());
  EXPECT_EQ(store->Backlog()->cycles, 0);
  // Sequence numbers are never reused, even after the queue was emptied.
  const int64_t next = OutboxCycle(*store, 1000, 1050);
  const std::vector<OutboxEntry> again = *store->ReadOutbox(10);
  ASSERT_EQ(again.size(), 1u);
  EXPECT_EQ(again[0].cycle.id, next);
  EXPECT_GT(again[0].seq, (*rest)[0].seq);
  EXPECT_EQ(store->ReadOutbox(0).status().code(), absl::StatusCode::kInvalidArgument);
}

TEST_F(StoreTest, OutboxCyclesAbortedAtOpenAreQueued) {
  int64_t interrupted = 0;
  {
    std::unique_ptr<Store> store = OpenOk(WithOutbox());
    OutboxCycle(*store, 1, 2);
    StoredCycle c;
    c.vin = "WVWZZZ1JZXW000001";
    c.car_model_id = "reference";
    c.request_json = "{}";
    interrupted = *store->BeginCycle(c);
  }
  std::unique_ptr<Store> store = OpenOk(WithOutbox());
  ASSERT_EQ(store->aborted_at_open(), 1);
  const std::vector<OutboxEntry> queued = *store->ReadOutbox(10);
  ASSERT_EQ(queued.size(), 2u);
  EXPECT_EQ(queued[1].cycle.id, interrupted);
  EXPECT_EQ(queued[1].cycle.state, CycleState::kAborted);
  EXPECT_EQ(queued[1].cycle.reason, "daemon_restarted");
}

// A version-1 file (made by turning a new file back into one: the same tables, no outbox)
// migrates to 2 and queues none of its old cycles; the ones that end afterwards are queued.
TEST_F(StoreTest, OutboxSchemaOneMigratesWithoutQueueingOldCycles) {
  {
    std::unique_ptr<Store> store = OpenOk();
    OutboxCycle(*store, 1, 2);
  }
  RawQuery("DROP TABLE outbox; DROP TABLE board_results; PRAGMA user_version = 1");
  ASSERT_EQ(RawQuery("SELECT COUNT(*) FROM sqlite_master WHERE name = 'outbox'"), "0");
  std::unique_ptr<Store> store = OpenOk(WithOutbox());
  EXPECT_EQ(RawQuery("PRAGMA user_version"), std::to_string(Store::kSchemaVersion));
  EXPECT_EQ(store->Backlog()->cycles, 0);
  const int64_t id = OutboxCycle(*store, 10, 20);
  const std::vector<OutboxEntry> queued = *store->ReadOutbox(10);
  ASSERT_EQ(queued.size(), 1u);
  EXPECT_EQ(queued[0].cycle.id, id);
  EXPECT_TRUE(store->IntegrityCheck().ok());
}

// A writer killed with SIGKILL while it ends cycles: every cycle stored as ended is queued
// exactly once and nothing else is (the end and the queue entry are one transaction).
TEST_F(StoreTest, OutboxKillNineLeavesTheQueueExactlyTheEndedCycles) {
  OpenOk(WithOutbox());  // the schema, before forking
  int fds[2];
  ASSERT_EQ(::pipe(fds), 0);
  const pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    ::close(fds[0]);
    absl::StatusOr<std::unique_ptr<Store>> store = Store::Open(path_, WithOutbox());
    if (!store.ok()) ::_exit(3);
    for (int64_t i = 0;; ++i) {
      const int64_t id = testing_daemon::EndCycleInStore(**store, i, i + 1);
      if (id == 0) ::_exit(4);
      if (::write(fds[1], &id, sizeof(id)) != sizeof(id)) ::_exit(6);
    }
  }
  ::close(fds[1]);
  int64_t id = 0;
  int reported = 0;
  // 30 cycles: mid-stream, and quick with five fsynced commits per cycle.
  while (reported < 30 && ::read(fds[0], &id, sizeof(id)) == sizeof(id)) ++reported;
  ::kill(child, SIGKILL);
  int status = 0;
  ::waitpid(child, &status, 0);
  ::close(fds[0]);
  ASSERT_TRUE(WIFSIGNALED(status)) << "writer exited early with " << WEXITSTATUS(status);
  ASSERT_EQ(reported, 30);

  std::unique_ptr<Store> store = OpenOk(WithOutbox());
  const std::vector<OutboxEntry> queued = *store->ReadOutbox(1000);
  std::map<int64_t, int> times_queued;
  int64_t previous = 0;
  for (const OutboxEntry& e : queued) {
    ++times_queued[e.cycle.id];
    EXPECT_GT(e.cycle.id, previous) << "queue order is not end order";
    previous = e.cycle.id;
    EXPECT_NE(e.cycle.state, CycleState::kRunning) << e.cycle.id;
  }
  const int64_t cycles = std::stoll(RawQuery("SELECT COUNT(*) FROM cycles"));
  EXPECT_GE(cycles, 30);
  EXPECT_EQ(static_cast<int64_t>(times_queued.size()), cycles);  // every one, ended or aborted
  for (const auto& [cycle, n] : times_queued) EXPECT_EQ(n, 1) << cycle;
}

}  // namespace
}  // namespace linecal

namespace linecal {
namespace {

// Trends read the solved results of the newest done cycles, oldest first, in one query:
// unsolved results (no T_car_sensor), running and cancelled cycles and older cycles are left
// out; the values are the stored doubles.
TEST_F(StoreTest, RecentSolvedResultsAreTheNewestDoneCyclesOldestFirst) {
  std::unique_ptr<Store> store = OpenOk();
  std::vector<int64_t> ids;
  for (int i = 0; i < 4; ++i) {
    absl::StatusOr<int64_t> id = store->BeginCycle(Request("WVWZZZ1JZXW000001", 1000 + i));
    ASSERT_TRUE(id.ok()) << id.status();
    ids.push_back(*id);
    StoredSensorResult camera = CameraResult();
    camera.residual_rms = 0.25 + i;
    ASSERT_TRUE(store->PutSensorResult(*id, camera).ok());
    StoredSensorResult unsolved;
    unsolved.sensor = "front_radar";
    unsolved.kind = SensorKind::kRadar;
    unsolved.verdict = Verdict::kError;
    ASSERT_TRUE(store->PutSensorResult(*id, unsolved).ok());
    const CycleState state = i == 2 ? CycleState::kCancelled : CycleState::kDone;
    ASSERT_TRUE(store->EndCycle(*id, state, Verdict::kFail, "", 5000 + i).ok());
  }
  ASSERT_TRUE(store->BeginCycle(Request("WVWZZZ1JZXW000001", 2000)).ok());  // running

  absl::StatusOr<std::vector<TrendRow>> rows = store->RecentSolvedResults(2);
  ASSERT_TRUE(rows.ok()) << rows.status();
  ASSERT_EQ(rows->size(), 2u);  // cycles 2 and 4 (3 was cancelled), the camera only
  EXPECT_EQ((*rows)[0].cycle_id, ids[1]);
  EXPECT_EQ((*rows)[1].cycle_id, ids[3]);
  EXPECT_EQ((*rows)[0].started_ns, 1001);
  EXPECT_EQ((*rows)[1].car_model_id, "reference");
  EXPECT_EQ((*rows)[1].sensor, "front_camera");
  EXPECT_EQ((*rows)[1].deviation, CameraResult().deviation);
  EXPECT_EQ((*rows)[1].residual_rms, 3.25);
  EXPECT_EQ(store->RecentSolvedResults(0).status().message(), "cycles = 0: must be in [1, 100000]");
  EXPECT_EQ(store->RecentSolvedResults(100001).status().code(), absl::StatusCode::kInvalidArgument);
}

// Replacing a sensor's result replaces its boards: none left from the first.
TEST_F(StoreTest, ReplacedSensorResultReplacesItsBoards) {
  std::unique_ptr<Store> store = OpenOk();
  absl::StatusOr<int64_t> id = store->BeginCycle(Request("WVWZZZ1JZXW000001", 1000));
  ASSERT_TRUE(id.ok()) << id.status();
  ASSERT_TRUE(store->PutSensorResult(*id, CameraResult()).ok());
  StoredSensorResult again = CameraResult();
  again.boards = {{"front_circle", 2, 2, 0, 0.0625}};
  ASSERT_TRUE(store->PutSensorResult(*id, again).ok());
  EXPECT_EQ(store->GetCycle(*id)->sensors.at(0), again);
  EXPECT_EQ(RawQuery("SELECT COUNT(*) FROM board_results"), "1");
}

// A version-2 file (a new file turned back: no board_results) with a cycle opens, migrates
// to 3, reads its old cycle without boards and stores the boards of new ones.
TEST_F(StoreTest, SchemaTwoMigratesToBoardResults) {
  int64_t old_id = 0;
  {
    std::unique_ptr<Store> store = OpenOk();
    old_id = *store->BeginCycle(Request("WVWZZZ1JZXW000001", 1000));
    StoredSensorResult camera = CameraResult();
    camera.boards.clear();
    ASSERT_TRUE(store->PutSensorResult(old_id, camera).ok());
    ASSERT_TRUE(store->EndCycle(old_id, CycleState::kDone, Verdict::kFail, "", 2000).ok());
  }
  RawQuery("DROP TABLE board_results; PRAGMA user_version = 2");
  ASSERT_EQ(RawQuery("SELECT COUNT(*) FROM sqlite_master WHERE name = 'board_results'"), "0");
  std::unique_ptr<Store> store = OpenOk();
  EXPECT_EQ(RawQuery("PRAGMA user_version"), "3");
  absl::StatusOr<StoredCycle> old = store->GetCycle(old_id);
  ASSERT_TRUE(old.ok()) << old.status();
  ASSERT_EQ(old->sensors.size(), 1u);
  EXPECT_TRUE(old->sensors[0].boards.empty());
  EXPECT_EQ(old->sensors[0].residual_rms, 0.187);
  const int64_t id = *store->BeginCycle(Request("WVWZZZ1JZXW000001", 3000));
  ASSERT_TRUE(store->PutSensorResult(id, CameraResult()).ok());
  EXPECT_EQ(store->GetCycle(id)->sensors.at(0).boards, CameraResult().boards);
  EXPECT_TRUE(store->IntegrityCheck().ok());
}

// Board trends: every board of every sensor (solved or not) of the newest done cycles, oldest
// first, by sensor and board, with whether the sensor was solved.
TEST_F(StoreTest, RecentBoardResultsAreTheNewestDoneCyclesBoards) {
  std::unique_ptr<Store> store = OpenOk();
  std::vector<int64_t> ids;
  for (int i = 0; i < 3; ++i) {
    const int64_t id = *store->BeginCycle(Request("WVWZZZ1JZXW000001", 1000 + i));
    ids.push_back(id);
    StoredSensorResult camera = CameraResult();
    camera.boards[0].residual_rms = 0.5 + i;
    ASSERT_TRUE(store->PutSensorResult(id, camera).ok());
    StoredSensorResult lidar;
    lidar.sensor = "bumper_lidar";
    lidar.kind = SensorKind::kLidar;
    lidar.verdict = Verdict::kError;
    lidar.boards = {{"bumper_lidar_left", 10, 0, 0, {}}};
    ASSERT_TRUE(store->PutSensorResult(id, lidar).ok());
    const CycleState state = i == 1 ? CycleState::kCancelled : CycleState::kDone;
    ASSERT_TRUE(store->EndCycle(id, state, Verdict::kFail, "", 5000 + i).ok());
  }
  absl::StatusOr<std::vector<BoardTrendRow>> rows = store->RecentBoardResults(1);
  ASSERT_TRUE(rows.ok()) << rows.status();
  ASSERT_EQ(rows->size(), 3u);  // the newest done cycle (3): the LiDAR's board, the camera's two
  EXPECT_EQ((*rows)[0].cycle_id, ids[2]);
  EXPECT_EQ((*rows)[0].started_ns, 1002);
  EXPECT_EQ((*rows)[0].car_model_id, "reference");
  EXPECT_EQ((*rows)[0].sensor, "bumper_lidar");
  EXPECT_FALSE((*rows)[0].solved);
  EXPECT_EQ((*rows)[0].board, (StoredBoardResult{"bumper_lidar_left", 10, 0, 0, {}}));
  EXPECT_EQ((*rows)[1].sensor, "front_camera");
  EXPECT_TRUE((*rows)[1].solved);
  EXPECT_EQ((*rows)[1].board, (StoredBoardResult{"bumper_lidar_left", 3, 2, 1, 2.5}));
  EXPECT_EQ((*rows)[2].board.board, "front_chessboard");
  EXPECT_EQ(store->RecentBoardResults(2)->front().cycle_id, ids[0]);
  EXPECT_EQ(store->RecentBoardResults(0).status().message(), "cycles = 0: must be in [1, 100000]");
}

}  // namespace
}  // namespace linecal
