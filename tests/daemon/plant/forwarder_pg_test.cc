// The forwarder against a real PostgreSQL 15 (a throwaway cluster per test,
// tests/support/postgres_cluster.h) and real station stores: every cycle arrives once and in
// order with the server up, stopped for 200 cycles, killed with SIGKILL mid-batch, behind a
// TCP proxy that stalls and drops connections; the station killed with SIGKILL mid-batch;
// a batch delivered twice; 10 stations at once; a plant schema older or newer than the
// station's. "Once" is checked on the plant's rows (cycles and events: a cycle sent twice
// would not add events either, so the events' count is checked too), "in order" on the
// plant's receive times (one transaction per batch: a later batch is never received
// before an earlier one).
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "daemon/core/station_core.h"
#include "daemon/plant/forwarder.h"
#include "daemon/service/station_service.h"
#include "tests/daemon/ended_cycle.h"
#include "tests/daemon/plant/tcp_proxy.h"
#include "tests/daemon/scratch_dir.h"
#include "tests/daemon/test_car.h"
#include "tests/support/postgres_cluster.h"
#include "tests/tools/run_linecal.h"

namespace linecal {
namespace {

namespace fs = std::filesystem;
using std::chrono::milliseconds;
using std::chrono::seconds;
using testing_support::PostgresCluster;

// How long a queue of a few thousand cycles may take to reach the plant in a test: the
// catch-up bar is 500 cycles/s, and the machine is shared with other builds.
constexpr seconds kArrivalTimeout{60};

class ForwarderPgTest : public ::testing::Test {
 protected:
  void SetUp() override {
    if (const std::string why = PostgresCluster::MissingReason(); !why.empty()) GTEST_SKIP() << why;
    dir_ = testing_daemon::FreshTestDir("linecal_forwarder_pg");
    absl::StatusOr<std::unique_ptr<PostgresCluster>> cluster = PostgresCluster::Create();
    ASSERT_TRUE(cluster.ok()) << cluster.status();
    cluster_ = *std::move(cluster);
    ASSERT_TRUE(cluster_->CreateDatabase("plant").ok());
    dsn_ = cluster_->Dsn("plant");
    absl::StatusOr<std::unique_ptr<PlantDb>> db = PlantDb::Connect(dsn_);
    ASSERT_TRUE(db.ok()) << db.status();
    ASSERT_TRUE((*db)->Migrate().ok());
  }
  void TearDown() override {
    cluster_.reset();
    fs::remove_all(dir_);
  }

  std::unique_ptr<Store> OpenStore(const std::string& name) {
    StoreOptions options;
    options.outbox = true;
    absl::StatusOr<std::unique_ptr<Store>> store = Store::Open((dir_ / name).string(), options);
    EXPECT_TRUE(store.ok()) << store.status();
    return store.ok() ? *std::move(store) : nullptr;
  }

  // Retries quickly, so that a test waits for arrivals, not for backoff.
  ForwarderOptions Options(const std::string& station, const std::string& conninfo) {
    ForwarderOptions o;
    o.conninfo = conninfo;
    o.station_id = station;
    o.batch = 20;
    o.first_retry_interval = milliseconds(20);
    o.max_retry_interval = milliseconds(200);
    o.log = [this](const LogRecord& record) {
      std::lock_guard<std::mutex> lock(log_mutex_);
      log_.push_back(LogLevelName(record.level) + std::string(": ") + record.message);
    };
    return o;
  }
  std::unique_ptr<Forwarder> Start(Store* store, const ForwarderOptions& o) {
    absl::StatusOr<std::unique_ptr<Forwarder>> f = Forwarder::Start(store, o);
    EXPECT_TRUE(f.ok()) << f.status();
    return f.ok() ? *std::move(f) : nullptr;
  }

  std::vector<int64_t> EndCycles(Store& store, int n, Forwarder* notify = nullptr) {
    std::vector<int64_t> ids;
    for (int i = 0; i < n; ++i) {
      const int64_t now = Now();
      ids.push_back(testing_daemon::EndCycleInStore(store, now - 1000, now));
      EXPECT_NE(ids.back(), 0);
      if (notify != nullptr) notify->Notify();
    }
    return ids;
  }

  static int64_t Now() {
    return std::chrono::duration_cast<std::chrono::nanoseconds>(
               std::chrono::system_clock::now().time_since_epoch())
        .count();
  }

  std::string Query(const std::string& sql) {
    absl::StatusOr<std::string> out = cluster_->Psql(dsn_, sql);
    EXPECT_TRUE(out.ok()) << sql << ": " << out.status();
    return out.ok() ? *out : "";
  }
  int64_t QueryInt(const std::string& sql) {
    int64_t v = -1;
    EXPECT_TRUE(absl::SimpleAtoi(Query(sql), &v)) << sql;
    return v;
  }

  // The station's cycle ids at the plant in the order they were received (ties, one batch,
  // by id).
  std::vector<int64_t> Received(const std::string& station) {
    std::vector<int64_t> ids;
    const std::string rows = Query(absl::StrCat("SELECT cycle_id FROM cycles WHERE station_id = '",
                                                station, "' ORDER BY received_at, cycle_id"));
    for (absl::string_view row : absl::StrSplit(rows, '\n', absl::SkipEmpty())) {
      int64_t id = 0;
      EXPECT_TRUE(absl::SimpleAtoi(row, &id)) << row;
      ids.push_back(id);
    }
    return ids;
  }

  // Every cycle of `ids` at the plant once with its 2 events, none other, in order.
  void ExpectArrivedOnceInOrder(const std::string& station, const std::vector<int64_t>& ids) {
    EXPECT_EQ(Received(station), ids);
    EXPECT_EQ(
        QueryInt(absl::StrCat("SELECT count(*) FROM events WHERE station_id = '", station, "'")),
        2 * static_cast<int64_t>(ids.size()));
    EXPECT_EQ(QueryInt(absl::StrCat("SELECT count(*) FROM sensor_results WHERE station_id = '",
                                    station, "'")),
              static_cast<int64_t>(ids.size()));
  }

  static bool WaitFor(const std::function<bool()>& done, std::chrono::milliseconds timeout) {
    const auto until = std::chrono::steady_clock::now() + timeout;
    while (!done()) {
      if (std::chrono::steady_clock::now() > until) return false;
      std::this_thread::sleep_for(milliseconds(10));
    }
    return true;
  }
  static bool Drained(Forwarder& f, std::chrono::milliseconds timeout = kArrivalTimeout) {
    return WaitFor([&] { return f.Stats().backlog == 0; }, timeout);
  }

  bool Logged(const std::string& text) {
    std::lock_guard<std::mutex> lock(log_mutex_);
    for (const std::string& line : log_) {
      if (line.find(text) != std::string::npos) return true;
    }
    return false;
  }

  fs::path dir_;
  std::unique_ptr<PostgresCluster> cluster_;
  std::string dsn_;
  std::mutex log_mutex_;
  std::vector<std::string> log_;
};

std::vector<int64_t> Concat(std::vector<int64_t> a, const std::vector<int64_t>& b) {
  a.insert(a.end(), b.begin(), b.end());
  return a;
}

TEST_F(ForwarderPgTest, EveryCycleArrivesOnceAndInOrderWithTheServerUp) {
  std::unique_ptr<Store> store = OpenStore("station.db");
  // Some queued before the forwarder starts, the rest while it runs.
  const std::vector<int64_t> before = EndCycles(*store, 30);
  std::unique_ptr<Forwarder> forwarder = Start(store.get(), Options("line1", dsn_));
  const std::vector<int64_t> after = EndCycles(*store, 70, forwarder.get());
  ASSERT_TRUE(Drained(*forwarder));
  ExpectArrivedOnceInOrder("line1", Concat(before, after));
  const ForwarderStats stats = forwarder->Stats();
  EXPECT_EQ(stats.shipped, 100);
  EXPECT_TRUE(stats.last_error.ok()) << stats.last_error;
  EXPECT_EQ(stats.oldest_unshipped_age, std::chrono::nanoseconds(0));

  // What the plant holds is what the station stored, field for field.
  absl::StatusOr<std::unique_ptr<PlantDb>> db = PlantDb::Connect(dsn_);
  ASSERT_TRUE(db.ok()) << db.status();
  absl::StatusOr<std::vector<PlantCycleRecord>> records = (*db)->CyclesSince(0, 1000);
  ASSERT_TRUE(records.ok()) << records.status();
  ASSERT_EQ(records->size(), 100u);
  for (const PlantCycleRecord& r : *records) {
    const StoredCycle stored = *store->GetCycle(r.cycle.id);
    EXPECT_EQ(r.station_id, "line1");
    EXPECT_EQ(r.cycle.vin, stored.vin);
    EXPECT_EQ(r.cycle.state, stored.state);
    EXPECT_EQ(r.cycle.ended_ns, stored.ended_ns);
    EXPECT_EQ(r.cycle.sensors, stored.sensors) << r.cycle.id;
  }
}

TEST_F(ForwarderPgTest, ServerStoppedFor200CyclesThenStartedDeliversEachOnceInOrder) {
  std::unique_ptr<Store> store = OpenStore("station.db");
  std::unique_ptr<Forwarder> forwarder = Start(store.get(), Options("line1", dsn_));
  const std::vector<int64_t> first = EndCycles(*store, 10, forwarder.get());
  ASSERT_TRUE(Drained(*forwarder));
  ASSERT_TRUE(cluster_->Stop().ok());
  const auto ending = std::chrono::steady_clock::now();
  const std::vector<int64_t> during = EndCycles(*store, 200, forwarder.get());
  // The station did not wait on the plant: 200 cycles end at the store's own pace (five
  // fsynced commits each), far below the plant's connect timeout per cycle.
  EXPECT_LT(std::chrono::steady_clock::now() - ending, seconds(60));
  ForwarderStats down = forwarder->Stats();
  EXPECT_EQ(down.backlog, 200);
  EXPECT_EQ(down.last_error.code(), absl::StatusCode::kUnavailable) << down.last_error;
  EXPECT_GT(down.oldest_unshipped_age, std::chrono::nanoseconds(0));
  EXPECT_TRUE(Logged("warning: plant database"));

  ASSERT_TRUE(cluster_->Start().ok());
  ASSERT_TRUE(Drained(*forwarder));
  ExpectArrivedOnceInOrder("line1", Concat(first, during));
  EXPECT_TRUE(forwarder->Stats().last_error.ok());
  // The counter may trail the emptied backlog by a moment (see DuplicateDelivery... below).
  EXPECT_TRUE(WaitFor([&] { return forwarder->Stats().shipped == 210; }, kArrivalTimeout))
      << forwarder->Stats().shipped;
  EXPECT_TRUE(Logged("info: plant database: reachable again"));
}

TEST_F(ForwarderPgTest, ServerKilledMidBatchLosesAndDuplicatesNothing) {
  std::unique_ptr<Store> store = OpenStore("station.db");
  const std::vector<int64_t> ids = EndCycles(*store, 1000);
  ForwarderOptions o = Options("line1", dsn_);
  o.batch = 50;
  std::unique_ptr<Forwarder> forwarder = Start(store.get(), o);
  ASSERT_TRUE(WaitFor([&] { return forwarder->Stats().shipped >= 50; }, kArrivalTimeout));
  ASSERT_TRUE(cluster_->Kill().ok());
  const int64_t left = forwarder->Stats().backlog;
  ASSERT_GT(left, 0) << "the queue was shipped before the kill; nothing was in flight";
  std::this_thread::sleep_for(milliseconds(300));  // attempts against a dead server
  ASSERT_TRUE(cluster_->Start().ok());             // crash recovery from the WAL
  ASSERT_TRUE(Drained(*forwarder));
  ExpectArrivedOnceInOrder("line1", ids);
  EXPECT_TRUE(Logged("warning: plant database"));
}

// The test's own proxy between the forwarder and the server stalls (nothing moves for 1.5 s:
// the call waits), then resets every connection (the call fails, maybe after the server
// committed), three times while the queue ships.
TEST_F(ForwarderPgTest, ProxyThatStallsAndDropsConnectionsLosesAndDuplicatesNothing) {
  absl::StatusOr<std::unique_ptr<testing_plant::TcpProxy>> proxy =
      testing_plant::TcpProxy::Start(cluster_->port());
  ASSERT_TRUE(proxy.ok()) << proxy.status();
  std::unique_ptr<Store> store = OpenStore("station.db");
  const std::vector<int64_t> ids = EndCycles(*store, 600);
  ForwarderOptions o = Options("line1", absl::StrCat(dsn_, " port=", (*proxy)->port()));
  o.batch = 10;
  std::unique_ptr<Forwarder> forwarder = Start(store.get(), o);
  for (int round = 0; round < 3; ++round) {
    ASSERT_TRUE(
        WaitFor([&] { return forwarder->Stats().shipped >= 50 * (round + 1); }, kArrivalTimeout));
    (*proxy)->SetStalled(true);
    std::this_thread::sleep_for(milliseconds(1500));
    (*proxy)->DropAll();
    (*proxy)->SetStalled(false);
  }
  ASSERT_TRUE(Drained(*forwarder));
  ExpectArrivedOnceInOrder("line1", ids);
  EXPECT_GE((*proxy)->accepted(), 4) << "every drop makes the forwarder reconnect";
  EXPECT_TRUE(Logged("warning: plant database"));
}

// The station process (a child owning a store and a forwarder) is killed with SIGKILL while
// it ships; a new one on the same store ships the rest: nothing lost, nothing twice.
TEST_F(ForwarderPgTest, StationKilledMidBatchAndRestartedLosesAndDuplicatesNothing) {
  std::vector<int64_t> ids;
  {
    std::unique_ptr<Store> store = OpenStore("station.db");
    ids = EndCycles(*store, 1000);
  }
  const pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    StoreOptions options;
    options.outbox = true;
    absl::StatusOr<std::unique_ptr<Store>> store =
        Store::Open((dir_ / "station.db").string(), options);
    if (!store.ok()) ::_exit(3);
    ForwarderOptions o;
    o.conninfo = dsn_;
    o.station_id = "line1";
    o.batch = 10;
    absl::StatusOr<std::unique_ptr<Forwarder>> f = Forwarder::Start(store->get(), o);
    if (!f.ok()) ::_exit(4);
    ::pause();  // until killed
    ::_exit(5);
  }
  // Killed once some batches arrived and most did not.
  const bool started =
      WaitFor([&] { return QueryInt("SELECT count(*) FROM cycles") >= 100; }, kArrivalTimeout);
  ::kill(child, SIGKILL);
  int status = 0;
  ::waitpid(child, &status, 0);
  ASSERT_TRUE(started);
  ASSERT_TRUE(WIFSIGNALED(status)) << "the station exited with " << WEXITSTATUS(status);
  const int64_t arrived = QueryInt("SELECT count(*) FROM cycles");
  ASSERT_LT(arrived, 1000) << "everything arrived before the kill";

  std::unique_ptr<Store> store = OpenStore("station.db");
  ASSERT_GT(store->Backlog()->cycles, 0);
  std::unique_ptr<Forwarder> forwarder = Start(store.get(), Options("line1", dsn_));
  ASSERT_TRUE(Drained(*forwarder));
  ExpectArrivedOnceInOrder("line1", ids);
}

// A batch that reached the plant but not MarkShipped (the station died in between) is sent
// again at the next start: the plant keeps the first copy, rows and receive times unchanged.
TEST_F(ForwarderPgTest, DuplicateDeliveryChangesNothingAtThePlant) {
  std::unique_ptr<Store> store = OpenStore("station.db");
  const std::vector<int64_t> ids = EndCycles(*store, 40);
  {
    absl::StatusOr<std::unique_ptr<PlantDb>> db = PlantDb::Connect(dsn_);
    ASSERT_TRUE(db.ok()) << db.status();
    std::vector<PlantCycle> batch;
    absl::StatusOr<std::vector<OutboxEntry>> first = store->ReadOutbox(25);
    ASSERT_TRUE(first.ok()) << first.status();
    for (OutboxEntry& e : *first) batch.push_back({e.cycle, e.events});
    ASSERT_TRUE((*db)->ApplyBatch("line1", batch).ok());
  }
  const std::string first_copy =
      Query("SELECT cycle_id, received_at FROM cycles ORDER BY cycle_id");
  std::this_thread::sleep_for(milliseconds(20));  // a second copy would get a later time
  std::unique_ptr<Forwarder> forwarder = Start(store.get(), Options("line1", dsn_));
  ASSERT_TRUE(Drained(*forwarder));
  // The 25 sent again, acknowledged again. Stats() reads the counter before the backlog, so
  // the backlog can read empty a moment before the last batch is counted: wait for the count.
  EXPECT_TRUE(WaitFor([&] { return forwarder->Stats().shipped == 40; }, kArrivalTimeout))
      << forwarder->Stats().shipped;
  ExpectArrivedOnceInOrder("line1", ids);
  const std::string now = Query("SELECT cycle_id, received_at FROM cycles WHERE cycle_id <= " +
                                std::to_string(ids[24]) + " ORDER BY cycle_id");
  EXPECT_EQ(now, first_copy);
}

TEST_F(ForwarderPgTest, TenStationsWritingAtOnceEachArriveOnceInOrder) {
  constexpr int kStations = 10;
  constexpr int kCycles = 60;
  std::vector<std::unique_ptr<Store>> stores;
  std::vector<std::unique_ptr<Forwarder>> forwarders;
  for (int s = 0; s < kStations; ++s) {
    stores.push_back(OpenStore(absl::StrCat("station", s, ".db")));
    ForwarderOptions o = Options(absl::StrCat("line", s), dsn_);
    o.batch = 5;  // many small transactions: the stations' commits interleave
    forwarders.push_back(Start(stores.back().get(), o));
  }
  std::vector<std::vector<int64_t>> ids(kStations);
  std::vector<std::thread> threads;
  for (int s = 0; s < kStations; ++s) {
    threads.emplace_back([&, s] { ids[s] = EndCycles(*stores[s], kCycles, forwarders[s].get()); });
  }
  for (std::thread& t : threads) t.join();
  for (int s = 0; s < kStations; ++s) {
    ASSERT_TRUE(Drained(*forwarders[s])) << s;
    ExpectArrivedOnceInOrder(absl::StrCat("line", s), ids[s]);
  }
  EXPECT_EQ(QueryInt("SELECT count(*) FROM stations"), kStations);
  EXPECT_EQ(QueryInt("SELECT count(*) FROM cycles"), kStations * kCycles);
}

// A plant at an older schema (not migrated) and one at a newer schema (a later linecal
// migrated it): the forwarder reports FailedPrecondition, keeps every cycle queued, and ships
// them all once the schema matches.
TEST_F(ForwarderPgTest, OlderOrNewerPlantSchemaKeepsTheBacklogUntilItMatches) {
  ASSERT_TRUE(cluster_->CreateDatabase("old_plant").ok());
  const std::string old_dsn = cluster_->Dsn("old_plant");
  std::unique_ptr<Store> store = OpenStore("station.db");
  const std::vector<int64_t> ids = EndCycles(*store, 15);
  std::unique_ptr<Forwarder> forwarder = Start(store.get(), Options("line1", old_dsn));
  ASSERT_TRUE(WaitFor([&] { return !forwarder->Stats().last_error.ok(); }, seconds(10)));
  ForwarderStats stats = forwarder->Stats();
  EXPECT_EQ(stats.last_error.code(), absl::StatusCode::kFailedPrecondition) << stats.last_error;
  EXPECT_NE(stats.last_error.message().find("older"), std::string::npos) << stats.last_error;
  EXPECT_EQ(stats.backlog, 15);
  forwarder.reset();

  // Newer: the plant database of SetUp, marked as migrated one version further.
  Query(absl::StrCat("INSERT INTO schema_migrations (version) VALUES (",
                     PlantDb::kSchemaVersion + 1, ")"));
  forwarder = Start(store.get(), Options("line1", dsn_));
  ASSERT_TRUE(WaitFor([&] { return !forwarder->Stats().last_error.ok(); }, seconds(10)));
  stats = forwarder->Stats();
  EXPECT_EQ(stats.last_error.code(), absl::StatusCode::kFailedPrecondition) << stats.last_error;
  EXPECT_NE(stats.last_error.message().find("newer"), std::string::npos) << stats.last_error;
  EXPECT_EQ(stats.backlog, 15);
  EXPECT_EQ(QueryInt("SELECT count(*) FROM cycles"), 0);

  Query(
      absl::StrCat("DELETE FROM schema_migrations WHERE version = ", PlantDb::kSchemaVersion + 1));
  ASSERT_TRUE(Drained(*forwarder));
  ExpectArrivedOnceInOrder("line1", ids);
  EXPECT_TRUE(forwarder->Stats().last_error.ok());
}

// A wrong password: PermissionDenied as the last error, which does not hold the password.
TEST_F(ForwarderPgTest, AuthenticationFailureIsReportedWithoutThePassword) {
  std::unique_ptr<Store> store = OpenStore("station.db");
  EndCycles(*store, 2);
  PlantConfig config;
  config.dsn =
      absl::StrCat("host=127.0.0.1 port=", cluster_->port(), " dbname=plant user=postgres");
  config.password = "wrong horse battery";
  absl::StatusOr<std::string> conninfo = PlantConnectionString(config);
  ASSERT_TRUE(conninfo.ok()) << conninfo.status();
  std::unique_ptr<Forwarder> forwarder = Start(store.get(), Options("line1", *conninfo));
  ASSERT_TRUE(WaitFor([&] { return !forwarder->Stats().last_error.ok(); }, seconds(10)));
  const ForwarderStats stats = forwarder->Stats();
  EXPECT_EQ(stats.last_error.code(), absl::StatusCode::kPermissionDenied) << stats.last_error;
  EXPECT_EQ(stats.last_error.message().find("wrong horse"), std::string::npos);
  EXPECT_EQ(stats.backlog, 2);
  std::lock_guard<std::mutex> lock(log_mutex_);
  for (const std::string& line : log_) {
    EXPECT_EQ(line.find("wrong horse"), std::string::npos) << line;
  }
}

// Stopping with a plant that answers drains the queue within the deadline; with a plant that
// stalls (the proxy), Stop returns by the deadline plus the in-flight grace and the cycles
// stay queued.
TEST_F(ForwarderPgTest, StopDrainsWhenThePlantAnswersAndNeverWaitsOnAStalledOne) {
  std::unique_ptr<Store> store = OpenStore("station.db");
  absl::StatusOr<std::unique_ptr<testing_plant::TcpProxy>> proxy =
      testing_plant::TcpProxy::Start(cluster_->port());
  ASSERT_TRUE(proxy.ok()) << proxy.status();
  ForwarderOptions o = Options("line1", absl::StrCat(dsn_, " port=", (*proxy)->port()));
  std::unique_ptr<Forwarder> forwarder = Start(store.get(), o);
  // The queue is empty, so the forwarder has not connected yet: its connection will stall
  // in the handshake.
  (*proxy)->SetStalled(true);
  const std::vector<int64_t> ids = EndCycles(*store, 30, forwarder.get());
  const auto before = std::chrono::steady_clock::now();
  EXPECT_EQ(forwarder->Stop(before + milliseconds(500)), 30);
  // 500 ms of drain, 500 ms of in-flight grace (kInFlightGrace), a margin for the machine.
  EXPECT_LT(std::chrono::steady_clock::now() - before, milliseconds(1500));
  forwarder.reset();
  (*proxy)->SetStalled(false);

  forwarder = Start(store.get(), Options("line1", dsn_));
  // Nothing new is notified: the queue left by the stop is shipped at start.
  ASSERT_TRUE(Drained(*forwarder));
  EXPECT_EQ(forwarder->Stop(std::chrono::steady_clock::now() + seconds(5)), 0);
  ExpectArrivedOnceInOrder("line1", ids);
}

// Two stations (StationCore, simulator source, the same request: the same simulated car)
// with the plant up for one and unreachable for the other: the station's answers and stored
// results are the same; only the forwarding differs, and health says so past
// max_backlog_age.
TEST_F(ForwarderPgTest, StationAnswersAndStoredResultsAreTheSameWithThePlantDown) {
  const std::string deploy = std::string(LINECAL_SOURCE_DIR) + "/deploy";
  testing_daemon::WriteTwoSensorCar((dir_ / "car.json").string(), "two_sensor");
  auto config = [&](const std::string& name, int port) {
    StationCoreConfig c;
    c.station_path = deploy + "/stations/reference.json";
    c.car_model_paths = {(dir_ / "car.json").string()};
    c.db_path = (dir_ / (name + ".db")).string();
    c.data_root = (dir_ / (name + "_data")).string();
    PlantConfig plant;
    plant.dsn = absl::StrCat("host=127.0.0.1 port=", port, " dbname=plant user=postgres");
    plant.password = PostgresCluster::kSuperuserPassword;
    plant.station_id = name;
    plant.max_backlog_age = seconds(1);
    plant.max_retry_interval = milliseconds(200);
    c.plant = plant;
    return c;
  };
  const int down_port = testing_plant::ClosedLoopbackPort();
  absl::StatusOr<std::unique_ptr<StationCore>> up =
      StationCore::Create(config("up", cluster_->port()));
  ASSERT_TRUE(up.ok()) << up.status();
  absl::StatusOr<std::unique_ptr<StationCore>> down =
      StationCore::Create(config("down", down_port));
  ASSERT_TRUE(down.ok()) << down.status();

  CycleRequest request;
  request.vin = "1M8GDM9AXKP042788";
  request.car_model_id = "two_sensor";
  request.aligner = {0.012, -0.008, 0.0009};
  absl::StatusOr<int64_t> up_id = (*up)->StartCycle(request);
  absl::StatusOr<int64_t> down_id = (*down)->StartCycle(request);
  ASSERT_TRUE(up_id.ok() && down_id.ok()) << up_id.status() << down_id.status();
  ASSERT_EQ(*up_id, *down_id);  // the simulator's seed: the same car in both
  (*up)->WaitIdle();
  (*down)->WaitIdle();

  StoredCycle a = *(*up)->GetCycle(*up_id);
  StoredCycle b = *(*down)->GetCycle(*down_id);
  EXPECT_EQ(a.state, CycleState::kDone);
  EXPECT_EQ(a.state, b.state);
  EXPECT_EQ(a.verdict, b.verdict);
  EXPECT_EQ(a.reason, b.reason);
  EXPECT_EQ(a.vin, b.vin);
  EXPECT_EQ(a.request_json, b.request_json);
  ASSERT_EQ(a.sensors.size(), 2u);
  for (StoredCycle* c : {&a, &b}) {
    for (StoredSensorResult& r : c->sensors) r.elapsed_ns = 0;  // wall time, not a result
  }
  EXPECT_EQ(a.sensors, b.sensors);  // poses, sigmas, verdicts, reasons: bit for bit
  // The events in order, without their times.
  auto events = [](StationCore& core, int64_t id) {
    std::vector<std::string> out;
    const absl::StatusOr<std::vector<StoredEvent>> stored = core.store().Events(id);
    EXPECT_TRUE(stored.ok()) << stored.status();
    if (!stored.ok()) return out;
    for (const StoredEvent& e : *stored) {
      out.push_back(absl::StrCat(EventTypeName(e.type), "|", e.sensor, "|", e.detail));
    }
    return out;
  };
  EXPECT_EQ(events(**up, *up_id), events(**down, *down_id));

  ASSERT_TRUE(WaitFor([&] { return (*up)->Status().plant->backlog == 0; }, kArrivalTimeout));
  EXPECT_EQ(Received("up"), std::vector<int64_t>{*up_id});
  std::this_thread::sleep_for(milliseconds(1100));  // past max_backlog_age (1 s)
  const StationStatusInfo status = (*down)->Status();
  ASSERT_TRUE(status.plant.has_value());
  EXPECT_EQ(status.plant->backlog, 1);
  EXPECT_EQ(status.plant->last_error.code(), absl::StatusCode::kUnavailable)
      << status.plant->last_error;
  EXPECT_EQ(status.plant_max_backlog_age, seconds(1));
  EXPECT_TRUE((*up)->Health().ok());
  const absl::Status health = (*down)->Health();
  EXPECT_EQ(health.code(), absl::StatusCode::kUnavailable);
  EXPECT_NE(health.message().find("plant database: 1 cycles not forwarded"), std::string::npos)
      << health;
  EXPECT_NE(health.message().find("plant.max_backlog_age_s 1"), std::string::npos) << health;
  // Over gRPC and on `linecal status` (the daemon's service on the same core).
  absl::StatusOr<RunningServer> server = StartServer(down->get(), "127.0.0.1:0", "", "test");
  ASSERT_TRUE(server.ok()) << server.status();
  const testing_tools::LinecalRun shown =
      testing_tools::RunLinecal(absl::StrCat("status --address 127.0.0.1:", server->port));
  EXPECT_EQ(shown.exit_code, 0) << shown.err;
  EXPECT_NE(shown.out.find("plant database: 1 cycles queued, oldest "), std::string::npos)
      << shown.out;
  EXPECT_NE(shown.out.find(" s (NOT_SERVING past 1 s), 0 shipped since start, last error: plant "
                           "database 127.0.0.1:"),
            std::string::npos)
      << shown.out;
  const testing_tools::LinecalRun json =
      testing_tools::RunLinecal(absl::StrCat("status --json --address 127.0.0.1:", server->port));
  EXPECT_NE(json.out.find("\"backlog\": \"1\""), std::string::npos) << json.out;
  EXPECT_NE(json.out.find("\"max_backlog_age_ns\": \"1000000000\""), std::string::npos) << json.out;
  server->server->Shutdown();
  *server = {};
  // Health does not stop the station: the next cycle runs and is stored.
  absl::StatusOr<int64_t> next = (*down)->StartCycle(request);
  ASSERT_TRUE(next.ok()) << next.status();
  (*down)->WaitIdle();
  EXPECT_EQ((*(*down)->GetCycle(*next)).state, CycleState::kDone);
}

}  // namespace
}  // namespace linecal
