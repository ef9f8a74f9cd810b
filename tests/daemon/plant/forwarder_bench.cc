// Forwarding to the plant database (docs/plant.md, "Forwarding") against a throwaway
// PostgreSQL 15 server on this machine (tests/support/postgres_cluster.h: fsync off, as a
// test server; the station's SQLite keeps synchronous=FULL). Built with the tests, run by
// hand, not by ctest:
//   BUILD/bin/daemon_forwarder_bench
//
//   OutboxDrain/10000   baseline: the station side alone: 10,000 queued cycles read and
//                       removed in batches of 100 (ReadOutbox + MarkShipped), no plant
//   CatchUp/10000       the same 10,000 shipped by a Forwarder (batch 100) into an empty plant
//                       database, start to empty outbox: bar >= 500 cycles/s (cycles_per_s)
//   PlantApply          baseline: one cycle applied with PlantDb::ApplyBatch directly, until
//                       a second connection reads its row
//   EndToEndLatency     a cycle's end committed in the station store to its row readable at
//                       the plant, through a running Forwarder: bar p95 <= 1 s
// The cycle time with forwarding on vs off is daemon_cycle_bench's CoreCycle/replay and
// CoreCycle/replay_forwarding.
#include <benchmark/benchmark.h>
#include <libpq-fe.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "absl/strings/str_cat.h"
#include "daemon/plant/forwarder.h"
#include "tests/daemon/bench_stats.h"
#include "tests/daemon/ended_cycle.h"
#include "tests/support/postgres_cluster.h"

namespace linecal {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;
using testing_support::PostgresCluster;

constexpr int kQueued = 10000;  // the backlog
constexpr int kBatch = 100;     // PlantConfig's default
// Single cycles for the latency percentiles: a p95 of 100 is the 95th smallest.
constexpr int kLatencyRepetitions = 100;

void Fail(const std::string& what) {
  std::fprintf(stderr, "daemon_forwarder_bench: %s\n", what.c_str());
  std::exit(2);
}

int64_t NowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

double Seconds(Clock::duration d) { return std::chrono::duration<double>(d).count(); }

struct Setup {
  fs::path dir;          // on disk: the stores the benchmarks run on
  fs::path template_db;  // kQueued cycles queued, made on tmpfs
  std::unique_ptr<PostgresCluster> plant;
  int databases = 0;  // plant databases made so far
};
Setup* g_setup = nullptr;

std::unique_ptr<Store> OpenStore(const fs::path& path) {
  StoreOptions options;
  options.outbox = true;
  absl::StatusOr<std::unique_ptr<Store>> store = Store::Open(path.string(), options);
  if (!store.ok()) Fail(store.status().ToString());
  return *std::move(store);
}

Setup& Shared() {
  if (g_setup != nullptr) return *g_setup;
  g_setup = new Setup;
  g_setup->dir =
      fs::temp_directory_path() / ("linecal_forwarder_bench_" + std::to_string(::getpid()));
  fs::remove_all(g_setup->dir);
  fs::create_directories(g_setup->dir);
  // The queue is made once on tmpfs (a store fsyncs five commits per cycle) and copied to
  // disk for each repetition, closed (checkpointed) first.
  const fs::path shm =
      fs::path("/dev/shm") / ("linecal_forwarder_bench_" + std::to_string(::getpid()));
  fs::create_directories(shm);
  {
    std::unique_ptr<Store> store = OpenStore(shm / "queued.db");
    const int64_t t0 = NowNs();
    for (int i = 0; i < kQueued; ++i) {
      if (testing_daemon::EndCycleInStore(*store, t0 + 2 * i, t0 + 2 * i + 1) == 0) {
        Fail("store refused a cycle");
      }
    }
  }
  g_setup->template_db = g_setup->dir / "queued.db";
  fs::copy_file(shm / "queued.db", g_setup->template_db);
  fs::remove_all(shm);
  absl::StatusOr<std::unique_ptr<PostgresCluster>> plant = PostgresCluster::Create();
  if (!plant.ok()) Fail(plant.status().ToString());
  g_setup->plant = *std::move(plant);
  return *g_setup;
}

// A new, migrated plant database; returns its libpq connection string.
std::string NewPlantDatabase() {
  Setup& s = Shared();
  const std::string name = absl::StrCat("plant", ++s.databases);
  if (absl::Status st = s.plant->CreateDatabase(name); !st.ok()) Fail(st.ToString());
  const std::string dsn = s.plant->Dsn(name);
  absl::StatusOr<std::unique_ptr<PlantDb>> db = PlantDb::Connect(dsn);
  if (!db.ok()) Fail(db.status().ToString());
  if (absl::Status st = (*db)->Migrate(); !st.ok()) Fail(st.ToString());
  return dsn;
}

// A copy of the queue of kQueued cycles, on disk.
fs::path CopyOfQueue(const std::string& name) {
  const fs::path path = Shared().dir / name;
  fs::remove(path);
  fs::copy_file(Shared().template_db, path);
  return path;
}

// Whether a cycle's row is at the plant, read on a connection of its own (as a report would).
class PlantReader {
 public:
  explicit PlantReader(const std::string& dsn) : conn_(PQconnectdb(dsn.c_str())) {
    if (PQstatus(conn_) != CONNECTION_OK) Fail(PQerrorMessage(conn_));
  }
  ~PlantReader() { PQfinish(conn_); }
  // Polls every millisecond until the row is there.
  void WaitFor(const std::string& station, int64_t cycle_id) {
    const std::string id = std::to_string(cycle_id);
    const char* params[] = {station.c_str(), id.c_str()};
    while (true) {
      PGresult* r =
          PQexecParams(conn_, "SELECT 1 FROM cycles WHERE station_id = $1 AND cycle_id = $2", 2,
                       nullptr, params, nullptr, nullptr, 0);
      const bool ok = PQresultStatus(r) == PGRES_TUPLES_OK;
      const bool found = ok && PQntuples(r) == 1;
      PQclear(r);
      if (!ok) Fail(PQerrorMessage(conn_));
      if (found) return;
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
  }

 private:
  PGconn* conn_;
};

// Repetitions of one measured run each (manual time), only the statistics printed.
benchmark::internal::Benchmark* Runs(benchmark::internal::Benchmark* b, int repetitions) {
  return b->Unit(benchmark::kMillisecond)
      ->UseManualTime()
      ->Iterations(1)
      ->Repetitions(repetitions)
      ->ComputeStatistics("p95", bench::P95)
      ->ComputeStatistics("max", bench::Max)
      ->ReportAggregatesOnly(true);
}

void BM_OutboxDrain(benchmark::State& state) {
  for (auto _ : state) {
    std::unique_ptr<Store> store = OpenStore(CopyOfQueue("drain.db"));
    const Clock::time_point start = Clock::now();
    int64_t read = 0;
    while (true) {
      absl::StatusOr<std::vector<OutboxEntry>> batch = store->ReadOutbox(kBatch);
      if (!batch.ok()) Fail(batch.status().ToString());
      if (batch->empty()) break;
      read += static_cast<int64_t>(batch->size());
      if (absl::Status s = store->MarkShipped(batch->back().seq); !s.ok()) Fail(s.ToString());
    }
    const double seconds = Seconds(Clock::now() - start);
    if (read != kQueued) Fail(absl::StrCat("drained ", read, " cycles"));
    state.SetIterationTime(seconds);
    state.counters["cycles_per_s"] = kQueued / seconds;
  }
}
const auto* const kOutboxDrain =
    Runs(benchmark::RegisterBenchmark("OutboxDrain/10000", BM_OutboxDrain), 3);

void BM_CatchUp(benchmark::State& state) {
  for (auto _ : state) {
    std::unique_ptr<Store> store = OpenStore(CopyOfQueue("catch_up.db"));
    ForwarderOptions options;
    options.conninfo = NewPlantDatabase();
    options.station_id = "bench";
    options.batch = kBatch;
    const Clock::time_point start = Clock::now();
    absl::StatusOr<std::unique_ptr<Forwarder>> forwarder = Forwarder::Start(store.get(), options);
    if (!forwarder.ok()) Fail(forwarder.status().ToString());
    // 10 ms between looks at the backlog: under 1% of the expected run.
    while ((*forwarder)->Stats().backlog > 0) {
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    const double seconds = Seconds(Clock::now() - start);
    const ForwarderStats stats = (*forwarder)->Stats();
    if (stats.shipped != kQueued || !stats.last_error.ok()) {
      Fail(absl::StrCat("shipped ", stats.shipped, ": ", stats.last_error.ToString()));
    }
    state.SetIterationTime(seconds);
    state.counters["cycles_per_s"] = kQueued / seconds;
  }
}
const auto* const kCatchUp = Runs(benchmark::RegisterBenchmark("CatchUp/10000", BM_CatchUp), 3);

void BM_PlantApply(benchmark::State& state) {
  static const std::string dsn = NewPlantDatabase();
  static std::unique_ptr<PlantDb> db = [] {
    absl::StatusOr<std::unique_ptr<PlantDb>> connected = PlantDb::Connect(dsn);
    if (!connected.ok()) Fail(connected.status().ToString());
    return *std::move(connected);
  }();
  static PlantReader reader(dsn);
  static int64_t next_id = 0;
  for (auto _ : state) {
    PlantCycle p;
    p.cycle.id = ++next_id;
    p.cycle.vin = "WVWZZZ1JZXW000001";
    p.cycle.car_model_id = "reference";
    p.cycle.state = CycleState::kDone;
    p.cycle.verdict = Verdict::kPass;
    p.cycle.started_ns = NowNs();
    p.cycle.ended_ns = p.cycle.started_ns + 1;
    p.cycle.request_json = "{}";
    const Clock::time_point start = Clock::now();
    if (absl::Status s = db->ApplyBatch("baseline", {p}); !s.ok()) Fail(s.ToString());
    reader.WaitFor("baseline", p.cycle.id);
    state.SetIterationTime(Seconds(Clock::now() - start));
  }
}
const auto* const kPlantApply =
    Runs(benchmark::RegisterBenchmark("PlantApply", BM_PlantApply), kLatencyRepetitions);

// The running station of EndToEndLatency: its store and forwarder, made on first use.
struct Station {
  std::unique_ptr<Store> store;
  std::unique_ptr<Forwarder> forwarder;
  std::unique_ptr<PlantReader> reader;
};
std::unique_ptr<Station> g_station;

void BM_EndToEndLatency(benchmark::State& state) {
  if (!g_station) {
    g_station = std::make_unique<Station>();
    const fs::path path = Shared().dir / "latency.db";
    g_station->store = OpenStore(path);
    ForwarderOptions options;
    options.conninfo = NewPlantDatabase();
    options.station_id = "latency";
    absl::StatusOr<std::unique_ptr<Forwarder>> forwarder =
        Forwarder::Start(g_station->store.get(), options);
    if (!forwarder.ok()) Fail(forwarder.status().ToString());
    g_station->forwarder = *std::move(forwarder);
    g_station->reader = std::make_unique<PlantReader>(options.conninfo);
  }
  for (auto _ : state) {
    const int64_t now = NowNs();
    // Returns once EndCycle committed (its last write): the clock starts there.
    const int64_t id = testing_daemon::EndCycleInStore(*g_station->store, now - 1000, now);
    if (id == 0) Fail("store refused a cycle");
    const Clock::time_point ended = Clock::now();
    g_station->forwarder->Notify();  // what StationCore does after the end is stored
    g_station->reader->WaitFor("latency", id);
    state.SetIterationTime(Seconds(Clock::now() - ended));
  }
}
const auto* const kEndToEndLatency =
    Runs(benchmark::RegisterBenchmark("EndToEndLatency", BM_EndToEndLatency), kLatencyRepetitions);

void Teardown() {
  g_station.reset();  // its forwarder stops before the server goes
  if (g_setup != nullptr) {
    g_setup->plant.reset();
    std::error_code ec;
    fs::remove_all(g_setup->dir, ec);
  }
}

}  // namespace
}  // namespace linecal

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  if (const std::string why = linecal::testing_support::PostgresCluster::MissingReason();
      !why.empty()) {
    std::fprintf(stderr, "daemon_forwarder_bench: %s\n", why.c_str());
    return 2;
  }
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  linecal::Teardown();
  return 0;
}
