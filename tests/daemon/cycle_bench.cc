// The daemon's cycle times for the reference car (deploy/stations/reference.json,
// deploy/cars/reference.json: 5 cameras, 2 LiDARs, 3 radars; one frame or rotation per
// sensor, the daemon's default), against docs/acceptance.md's bars (docs/performance.md has the
// table). Built with the tests, run by hand, not by ctest:
//   BUILD/bin/daemon_cycle_bench
//
//   ReadCaptureData        baseline: reading and decoding every file of the capture, one
//                          thread, no detection (the floor under a cycle's compute)
//   CalibrateCapture/threads:8  compute per cycle as the daemon runs it (8 sensor threads):
//                          bar p95 of 50 <= 1.0 s; per-sensor wall times as counters (ms)
//   CalibrateCapture/threads:2, threads:1  the same with one thread per core of this
//                          machine, and one sensor after the other (the parallel gain)
// Every CalibrateCapture also reports the process's CPU time per cycle (cpu_ms, all threads),
// which other processes' load on the machine does not inflate.
//   CoreCycle/replay       end to end in StationCore: StartCycle -> stored end (WaitIdle),
//                          replay source, real SQLite file (fsync on every commit)
//   GrpcCycle/replay       end to end through gRPC on loopback: StartCycle, WatchCycle to
//                          the cycle_ended event, GetCycle (what `linecal cycle start
//                          --wait` does): bar <= 3 s
//   CoreCycle/replay_forwarding  the same with forwarding to a plant PostgreSQL (a throwaway
//                          server, up): bar within 5% of CoreCycle/replay (docs/plant.md)
//   CoreCycle/simulator    StationCore with the simulator source: rendering every sensor
//                          included (the demo's cycle, not a station's)
// The capture is simulated once (seed 1) into a scratch directory, removed at exit.
#include <benchmark/benchmark.h>
#include <grpcpp/grpcpp.h>
#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "daemon/core/station_core.h"
#include "daemon/service/station_service.h"
#include "linecal/v1/station.grpc.pb.h"
#include "station/capture/capture.h"
#include "station/io/candump.h"
#include "station/io/image_io.h"
#include "station/pipeline/capture_calibration.h"
#include "station/sensors/lidar/pcd.h"
#include "station/sim/simulator.h"
#include "tests/daemon/bench_stats.h"
#include "tests/support/postgres_cluster.h"

namespace linecal {
namespace {

namespace fs = std::filesystem;

const std::string kDeploy = std::string(LINECAL_SOURCE_DIR) + "/deploy";
constexpr char kVin[] = "1M8GDM9AXKP042788";
// docs/acceptance.md: compute per cycle is judged on the p95 of 50 cycles.
constexpr int kComputeRepetitions = 50;
// End to end: enough cycles for a p95 that means something, few enough for a shared machine.
constexpr int kEndToEndRepetitions = 20;

using bench::Cycles;

// User and system CPU time of the whole process (every thread), seconds.
double ProcessCpuSeconds() {
  rusage u{};
  ::getrusage(RUSAGE_SELF, &u);
  const auto seconds = [](const timeval& t) { return t.tv_sec + t.tv_usec * 1e-6; };
  return seconds(u.ru_utime) + seconds(u.ru_stime);
}

void Fail(const std::string& what) {
  std::fprintf(stderr, "daemon_cycle_bench: %s\n", what.c_str());
  std::exit(2);
}

// The scratch directory: data/reference is the simulated capture (the replay sources' too).
struct Setup {
  fs::path dir;
  Capture capture;
};

const Setup& Reference() {
  static const Setup* setup = [] {
    auto* s = new Setup;
    s->dir = fs::temp_directory_path() / ("linecal_cycle_bench_" + std::to_string(::getpid()));
    fs::remove_all(s->dir);
    const fs::path capture_dir = s->dir / "data" / "reference";
    fs::create_directories(capture_dir);
    absl::StatusOr<StationLayout> station = ReadStationLayout(kDeploy + "/stations/reference.json");
    absl::StatusOr<CarModel> car = ReadCarModel(kDeploy + "/cars/reference.json");
    if (!station.ok() || !car.ok())
      Fail(station.status().ToString() + " " + car.status().ToString());
    SimulatorOptions o;
    o.camera_frames = 1;  // the daemon's default frames per sensor
    o.lidar.rotations = 1;
    if (absl::Status st = SimulateCapture(*station, *car, o, 1, capture_dir.string()).status();
        !st.ok()) {
      Fail(st.ToString());
    }
    absl::StatusOr<Capture> capture = ReadCapture(capture_dir.string());
    if (!capture.ok()) Fail(capture.status().ToString());
    s->capture = *std::move(capture);
    return s;
  }();
  return *setup;
}

StationCoreConfig CoreConfig(const std::string& name, CycleSource source) {
  StationCoreConfig c;
  c.station_path = kDeploy + "/stations/reference.json";
  c.car_model_paths = {kDeploy + "/cars/reference.json"};
  c.db_path = (Reference().dir / (name + ".db")).string();
  c.data_root = (Reference().dir / "data").string();
  c.source = source;
  if (source == CycleSource::kReplay) c.replay_capture = "reference";
  return c;
}

std::unique_ptr<StationCore> MakeCore(const std::string& name, CycleSource source) {
  absl::StatusOr<std::unique_ptr<StationCore>> core = StationCore::Create(CoreConfig(name, source));
  if (!core.ok()) Fail(core.status().ToString());
  return *std::move(core);
}

CycleRequest Request() {
  CycleRequest r;
  r.vin = kVin;
  r.car_model_id = "reference";
  r.aligner = {0.004, -0.006, 0.0005};
  return r;
}

void BM_ReadCaptureData(benchmark::State& state) {
  const Setup& setup = Reference();
  for (auto _ : state) {
    absl::StatusOr<Capture> capture = ReadCapture(setup.capture.dir);
    if (!capture.ok()) Fail(capture.status().ToString());
    for (const CaptureSensor& s : capture->manifest.sensors) {
      for (const CaptureFile& f : s.frames) {
        if (s.kind == SensorKind::kCamera) {
          benchmark::DoNotOptimize(ReadImage8(capture->PathOf(f)));
        } else {
          benchmark::DoNotOptimize(ReadPcd(capture->PathOf(f)));
        }
      }
      if (s.can_log) benchmark::DoNotOptimize(ReadCandumpLog(capture->PathOf(*s.can_log)));
    }
  }
}
const auto* const kReadCaptureData = Cycles(
    benchmark::RegisterBenchmark("ReadCaptureData", BM_ReadCaptureData), kComputeRepetitions);

void BM_CalibrateCapture(benchmark::State& state) {
  const Setup& setup = Reference();
  CaptureCalibrationOptions options;
  options.threads = static_cast<int>(state.range(0));
  CycleCalibration last;
  const double cpu_before_s = ProcessCpuSeconds();
  for (auto _ : state) {
    absl::StatusOr<CycleCalibration> cycle = CalibrateCapture(setup.capture, options);
    if (!cycle.ok()) Fail(cycle.status().ToString());
    last = *std::move(cycle);
  }
  // The CPU the cycle took on all cores: unlike the wall time, not inflated by other
  // processes' load on the shared machine.
  state.counters["cpu_ms"] = (ProcessCpuSeconds() - cpu_before_s) * 1e3;
  // Where the time goes: each sensor's detection and solve, wall milliseconds (with 8
  // threads on 2 cores they overlap, so they add up to more than the cycle).
  for (const SensorCalibration& s : last.sensors)
    state.counters["ms_" + s.name] = s.elapsed_ns * 1e-6;
  int passed = 0;
  for (const SensorCalibration& s : last.sensors) passed += s.verdict == Verdict::kPass;
  state.counters["sensors_passed"] = passed;
}
// 8 threads: CaptureCalibrationOptions' default, what the daemon runs.
const auto* const kCalibrateCapture8 =
    Cycles(benchmark::RegisterBenchmark("CalibrateCapture", BM_CalibrateCapture)
               ->ArgName("threads")
               ->Arg(8),
           kComputeRepetitions);
// One thread per core of this machine, and one in all: how the default compares. 10
// repetitions each: no bar on them.
const auto* const kCalibrateCapture2 =
    Cycles(benchmark::RegisterBenchmark("CalibrateCapture", BM_CalibrateCapture)
               ->ArgName("threads")
               ->Arg(2),
           10);
const auto* const kCalibrateCapture1 =
    Cycles(benchmark::RegisterBenchmark("CalibrateCapture", BM_CalibrateCapture)
               ->ArgName("threads")
               ->Arg(1),
           10);

void RunCoreCycles(benchmark::State& state, StationCore& core) {
  for (auto _ : state) {
    absl::StatusOr<int64_t> id = core.StartCycle(Request());
    if (!id.ok()) Fail(id.status().ToString());
    core.WaitIdle();
    absl::StatusOr<StoredCycle> cycle = core.GetCycle(*id);
    if (!cycle.ok() || cycle->state != CycleState::kDone)
      Fail("cycle did not end done: " + cycle->reason);
  }
}

// The cores and the server the benchmarks share, made on first use, torn down by main before
// the scratch directory goes (a server's threads must not outlive their core).
struct Served {
  std::unique_ptr<StationCore> core;
  RunningServer server;
  std::unique_ptr<v1::Station::Stub> stub;
};
std::unique_ptr<StationCore> g_replay_core, g_simulator_core, g_forwarding_core;
std::unique_ptr<Served> g_served;
// The plant database of CoreCycle/replay_forwarding: a throwaway PostgreSQL 15 server.
std::unique_ptr<testing_support::PostgresCluster> g_plant;

void Teardown() {
  if (g_served) g_served->server.server->Shutdown();
  g_served.reset();
  g_replay_core.reset();
  g_simulator_core.reset();
  g_forwarding_core.reset();  // stops its forwarder before the server goes
  g_plant.reset();
}

void BM_CoreCycleReplay(benchmark::State& state) {
  if (!g_replay_core) g_replay_core = MakeCore("core_replay", CycleSource::kReplay);
  RunCoreCycles(state, *g_replay_core);
}
const auto* const kCoreCycleReplay = Cycles(
    benchmark::RegisterBenchmark("CoreCycle/replay", BM_CoreCycleReplay), kEndToEndRepetitions);

// The same with a `plant` section, the plant database up: each end also queues the cycle in
// the outbox (same transaction) and the forwarder ships it while the next cycle runs.
void BM_CoreCycleReplayForwarding(benchmark::State& state) {
  if (!g_forwarding_core) {
    absl::StatusOr<std::unique_ptr<testing_support::PostgresCluster>> plant =
        testing_support::PostgresCluster::Create();
    if (!plant.ok()) Fail(plant.status().ToString());
    g_plant = *std::move(plant);
    if (absl::Status s = g_plant->CreateDatabase("plant"); !s.ok()) Fail(s.ToString());
    absl::StatusOr<std::unique_ptr<PlantDb>> db = PlantDb::Connect(g_plant->Dsn("plant"));
    if (!db.ok()) Fail(db.status().ToString());
    if (absl::Status s = (*db)->Migrate(); !s.ok()) Fail(s.ToString());
    StationCoreConfig config = CoreConfig("core_forwarding", CycleSource::kReplay);
    PlantConfig forwarding;
    forwarding.dsn =
        "host=127.0.0.1 port=" + std::to_string(g_plant->port()) + " dbname=plant user=postgres";
    forwarding.password = testing_support::PostgresCluster::kSuperuserPassword;
    forwarding.station_id = "bench";
    config.plant = forwarding;
    absl::StatusOr<std::unique_ptr<StationCore>> core = StationCore::Create(config);
    if (!core.ok()) Fail(core.status().ToString());
    g_forwarding_core = *std::move(core);
  }
  RunCoreCycles(state, *g_forwarding_core);
  const ForwarderStats stats = *g_forwarding_core->Status().plant;
  if (!stats.last_error.ok()) Fail("forwarding failed: " + stats.last_error.ToString());
  state.counters["shipped"] = static_cast<double>(stats.shipped);
}
const auto* const kCoreCycleReplayForwarding = Cycles(
    benchmark::RegisterBenchmark("CoreCycle/replay_forwarding", BM_CoreCycleReplayForwarding),
    kEndToEndRepetitions);

void BM_GrpcCycleReplay(benchmark::State& state) {
  if (!g_served) {
    g_served = std::make_unique<Served>();
    g_served->core = MakeCore("grpc_replay", CycleSource::kReplay);
    absl::StatusOr<RunningServer> server =
        StartServer(g_served->core.get(), "127.0.0.1:0", "", "bench");
    if (!server.ok()) Fail(server.status().ToString());
    g_served->server = *std::move(server);
    g_served->stub = v1::Station::NewStub(grpc::CreateChannel(
        "127.0.0.1:" + std::to_string(g_served->server.port), grpc::InsecureChannelCredentials()));
  }
  Served* served = g_served.get();
  for (auto _ : state) {
    v1::StartCycleRequest request;
    request.set_vin(kVin);
    request.set_car_model_id("reference");
    v1::StartCycleResponse started;
    grpc::ClientContext start_context;
    if (grpc::Status s = served->stub->StartCycle(&start_context, request, &started); !s.ok())
      Fail(s.error_message());
    v1::WatchCycleRequest watch;
    watch.set_cycle_id(started.cycle_id());
    grpc::ClientContext watch_context;
    std::unique_ptr<grpc::ClientReader<v1::CycleEvent>> reader =
        served->stub->WatchCycle(&watch_context, watch);
    v1::CycleEvent event;
    bool ended = false;
    while (reader->Read(&event)) ended |= event.type() == v1::CycleEvent::TYPE_CYCLE_ENDED;
    if (grpc::Status s = reader->Finish(); !s.ok() || !ended) Fail("watch: " + s.error_message());
    v1::GetCycleRequest get;
    get.set_cycle_id(started.cycle_id());
    v1::Cycle cycle;
    grpc::ClientContext get_context;
    if (grpc::Status s = served->stub->GetCycle(&get_context, get, &cycle); !s.ok())
      Fail(s.error_message());
    if (cycle.state() != v1::CYCLE_STATE_DONE || cycle.sensors_size() != 10)
      Fail("cycle did not end done");
  }
}
const auto* const kGrpcCycleReplay = Cycles(
    benchmark::RegisterBenchmark("GrpcCycle/replay", BM_GrpcCycleReplay), kEndToEndRepetitions);

void BM_CoreCycleSimulator(benchmark::State& state) {
  if (!g_simulator_core) g_simulator_core = MakeCore("core_simulator", CycleSource::kSimulator);
  RunCoreCycles(state, *g_simulator_core);
}
// 5 repetitions: seconds each (the renders); shown for the demo, no bar on it.
const auto* const kCoreCycleSimulator =
    Cycles(benchmark::RegisterBenchmark("CoreCycle/simulator", BM_CoreCycleSimulator), 5);

}  // namespace
}  // namespace linecal

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  linecal::Teardown();
  std::error_code ec;
  std::filesystem::remove_all(std::filesystem::temp_directory_path() /
                                  ("linecal_cycle_bench_" + std::to_string(::getpid())),
                              ec);
  return 0;
}
