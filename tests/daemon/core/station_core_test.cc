// The station core with real parts: the reference station, a car model with the reference
// front camera and front radar (a short cycle), the simulator and replay sources, a real
// SQLite file. Cycles run to a stored verdict; events stream in order; requests are
// validated naming the field; one cycle at a time; the daemon's results equal the offline
// calibration of the same capture.
#include "daemon/core/station_core.h"

#include <gtest/gtest.h>
#include <sqlite3.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <numbers>
#include <string>
#include <thread>

#include "station/capture/capture.h"
#include "station/pipeline/capture_calibration.h"
#include "station/sim/simulator.h"
#include "tests/daemon/scratch_dir.h"
#include "tests/daemon/test_car.h"

namespace linecal {
namespace {

namespace fs = std::filesystem;
const std::string kDeploy = std::string(LINECAL_SOURCE_DIR) + "/deploy";
// A valid VIN with its ISO 3779 check digit (position 9).
constexpr char kVin[] = "1M8GDM9AXKP042788";

class StationCoreTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = testing_daemon::FreshTestDir("core");
    // The reference car with two sensors only: a cycle of well under a second.
    testing_daemon::WriteTwoSensorCar((dir_ / "car.json").string(), "two_sensor");
    config_.station_path = kDeploy + "/stations/reference.json";
    config_.car_model_paths = {(dir_ / "car.json").string()};
    config_.db_path = (dir_ / "station.db").string();
    config_.data_root = (dir_ / "data").string();
  }
  void TearDown() override { fs::remove_all(dir_); }

  std::unique_ptr<StationCore> Core() {
    absl::StatusOr<std::unique_ptr<StationCore>> core = StationCore::Create(config_);
    EXPECT_TRUE(core.ok()) << core.status();
    return core.ok() ? std::move(*core) : nullptr;
  }

  // The replay source on a capture of the reference car's front camera and front radar
  // (seed 9), recorded as data_root/recorded; returns its directory.
  fs::path UseReplay() {
    SimulatorOptions o;
    o.sensors = {"front_camera", "front_radar"};
    const fs::path rec = fs::path(config_.data_root) / "recorded";
    fs::create_directories(config_.data_root);
    const absl::Status simulated =
        SimulateCapture(*ReadStationLayout(config_.station_path),
                        *ReadCarModel(kDeploy + "/cars/reference.json"), o, 9, rec.string())
            .status();
    EXPECT_TRUE(simulated.ok()) << simulated;
    config_.source = CycleSource::kReplay;
    config_.replay_capture = "recorded";
    config_.car_model_paths = {kDeploy + "/cars/reference.json"};
    return rec;
  }

  static CycleRequest Request() {
    CycleRequest r;
    r.vin = kVin;
    r.car_model_id = "two_sensor";
    r.aligner = {0.012, -0.008, 0.05 * std::numbers::pi / 180};
    return r;
  }

  fs::path dir_;
  StationCoreConfig config_;
};

// The stored per-sensor results equal CalibrateCapture's on the same capture.
void ExpectSameResults(const StoredCycle& stored, const CycleCalibration& offline) {
  ASSERT_EQ(stored.sensors.size(), offline.sensors.size());
  for (const SensorCalibration& s : offline.sensors) {
    SCOPED_TRACE(s.name);
    const StoredSensorResult* r = nullptr;
    for (const StoredSensorResult& x : stored.sensors) {
      if (x.sensor == s.name) r = &x;
    }
    ASSERT_NE(r, nullptr);
    EXPECT_EQ(r->verdict == Verdict::kPass, s.verdict == Verdict::kPass);
    EXPECT_EQ(r->reason, s.reason);
    EXPECT_EQ(r->features_used, s.features_used);
    EXPECT_EQ(r->residual_rms, s.residual_rms);  // bit for bit: the same code on the same bytes
    ASSERT_EQ(r->T_car_sensor.size(), 16u);
    const Eigen::Matrix4d T = s.mounting.T_car_sensor.Matrix();
    for (int i = 0; i < 16; ++i) EXPECT_EQ(r->T_car_sensor[i], T(i / 4, i % 4)) << i;
  }
}

TEST_F(StationCoreTest, SimulatedCycleIsStoredWithItsEventsAndEqualsTheOfflineResult) {
  std::unique_ptr<StationCore> core = Core();
  CycleRequest request = Request();
  request.record_capture = true;
  absl::StatusOr<int64_t> id = core->StartCycle(request);
  ASSERT_TRUE(id.ok()) << id.status();
  std::vector<std::string> types;
  std::vector<int64_t> sequences;
  ASSERT_TRUE(core->WatchCycle(*id,
                               [&](const StoredEvent& e) {
                                 types.push_back(
                                     EventTypeName(e.type) +
                                     std::string(e.sensor.empty() ? "" : ":" + e.sensor));
                                 sequences.push_back(e.sequence);
                                 return true;
                               })
                  .ok());
  EXPECT_EQ(types.front(), "started");
  EXPECT_EQ(types.back(), "cycle_ended");
  EXPECT_NE(std::find(types.begin(), types.end(), "sensor_acquired:front_camera"), types.end());
  EXPECT_NE(std::find(types.begin(), types.end(), "sensor_verdict:front_radar"), types.end());
  for (size_t i = 0; i < sequences.size(); ++i) EXPECT_EQ(sequences[i], static_cast<int64_t>(i));

  absl::StatusOr<StoredCycle> cycle = core->GetCycle(*id);
  ASSERT_TRUE(cycle.ok());
  EXPECT_EQ(cycle->state, CycleState::kDone);
  EXPECT_EQ(cycle->vin, kVin);
  EXPECT_GT(cycle->ended_ns, cycle->started_ns);
  ASSERT_EQ(cycle->sensors.size(), 2u);
  EXPECT_NE(cycle->request_json.find("\"lateral_offset_m\":-0.008"), std::string::npos)
      << cycle->request_json;

  // The recorded capture holds the request's aligner, and calibrating it offline gives the
  // stored results exactly.
  absl::StatusOr<Capture> capture =
      ReadCapture((fs::path(config_.data_root) / cycle->capture_path).string());
  ASSERT_TRUE(capture.ok()) << capture.status();
  EXPECT_DOUBLE_EQ(capture->manifest.aligner.lateral_offset_m, -0.008);
  absl::StatusOr<CycleCalibration> offline = CalibrateCapture(*capture);
  ASSERT_TRUE(offline.ok());
  ExpectSameResults(*cycle, *offline);
  EXPECT_EQ(cycle->verdict == Verdict::kPass, offline->verdict == Verdict::kPass);
}

TEST_F(StationCoreTest, ReplaySourceGivesTheOfflineResult) {
  const fs::path rec = UseReplay();
  std::unique_ptr<StationCore> core = Core();
  CycleRequest request = Request();
  request.car_model_id = "reference";
  const int64_t id = *core->StartCycle(request);
  core->WaitIdle();
  absl::StatusOr<StoredCycle> cycle = core->GetCycle(id);
  ASSERT_TRUE(cycle.ok());
  EXPECT_EQ(cycle->state, CycleState::kDone);
  EXPECT_EQ(cycle->capture_path, "recorded");
  ExpectSameResults(*cycle, *CalibrateCapture(*ReadCapture(rec.string())));

  // A replay capture outside the data root is refused at start-up.
  config_.replay_capture = "../elsewhere";
  const absl::Status escape = StationCore::Create(config_).status();
  EXPECT_EQ(escape.code(), absl::StatusCode::kInvalidArgument);
  // Named as the configuration file calls the key (docs/daemon.md), not as the struct does.
  EXPECT_EQ(escape.message().rfind("source.capture: '../elsewhere'", 0), 0u) << escape.message();
}

TEST_F(StationCoreTest, RequestsAreValidatedNamingTheField) {
  std::unique_ptr<StationCore> core = Core();
  auto expect_field = [&](CycleRequest r, const std::string& field) {
    const absl::Status s = core->StartCycle(r).status();
    EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument) << field;
    EXPECT_EQ(s.message().rfind(field, 0), 0u) << s.message();
  };
  CycleRequest r = Request();
  r.vin = "1M8GDM9AXKP04278O";  // the letter O is not allowed
  expect_field(r, "vin");
  r = Request();
  r.vin = "1M8GDM9AXKP042789";  // wrong check digit
  expect_field(r, "vin");
  r = Request();
  r.car_model_id = "sedan";
  expect_field(r, "car_model_id");
  r = Request();
  r.aligner.lateral_offset_m = 2.5;
  expect_field(r, "aligner.lateral_offset_m");
  r = Request();
  r.aligner.thrust_angle_rad = std::nan("");
  expect_field(r, "aligner.thrust_angle_deg");
  r = Request();
  r.frames_per_sensor = 101;
  expect_field(r, "options.frames_per_sensor");
  // Nothing was stored for refused requests.
  EXPECT_TRUE(core->ListCycles({})->cycles.empty());
}

TEST_F(StationCoreTest, OneCycleAtATimeCancelAndUnknownIds) {
  std::unique_ptr<StationCore> core = Core();
  const int64_t first = *core->StartCycle(Request());
  const absl::Status second = core->StartCycle(Request()).status();
  EXPECT_EQ(second.code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_NE(second.message().find(std::to_string(first)), std::string::npos);
  EXPECT_EQ(core->Status().running_cycle, std::optional<int64_t>(first));
  ASSERT_TRUE(core->CancelCycle(first).ok());
  core->WaitIdle();
  absl::StatusOr<StoredCycle> cancelled = core->GetCycle(first);
  EXPECT_EQ(cancelled->state, CycleState::kCancelled);
  EXPECT_EQ(cancelled->reason, "cancelled");
  EXPECT_EQ(core->CancelCycle(first).code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_EQ(core->GetCycle(999).status().code(), absl::StatusCode::kNotFound);
  EXPECT_EQ(core->CancelCycle(999).code(), absl::StatusCode::kNotFound);
  EXPECT_EQ(core->WatchCycle(999, [](const StoredEvent&) { return true; }).code(),
            absl::StatusCode::kNotFound);
  // The station takes the next car.
  const int64_t next = *core->StartCycle(Request());
  EXPECT_GT(next, first);
  core->WaitIdle();
  const StationStatusInfo status = core->Status();
  EXPECT_EQ(status.car_models, std::vector<std::string>{"two_sensor"});
  EXPECT_EQ(status.running_cycle, std::nullopt);
  EXPECT_GT(status.disk_free_bytes, 0u);
}

// Another process holds the database's write lock past the busy timeout while a cycle runs:
// the cycle cannot store its results, ends in error with reason store_unavailable, and that
// end is stored once the lock is gone (the station stays busy until then, never idle with
// the cycle left running).
TEST_F(StationCoreTest, DatabaseLockedMidCycleEndsInErrorStoredOnceTheLockIsGone) {
  config_.busy_timeout = std::chrono::milliseconds(100);
  std::unique_ptr<StationCore> core = Core();
  // A clean cycle first: how long one takes on this machine and build (sanitizers included).
  const auto t0 = std::chrono::steady_clock::now();
  const int64_t clean = *core->StartCycle(Request());
  core->WaitIdle();
  const auto cycle_time = std::chrono::steady_clock::now() - t0;
  ASSERT_EQ(core->GetCycle(clean)->state, CycleState::kDone);

  const int64_t id = *core->StartCycle(Request());
  sqlite3* other = nullptr;
  ASSERT_EQ(sqlite3_open(config_.db_path.c_str(), &other), SQLITE_OK);
  sqlite3_busy_timeout(other, 5000);  // the cycle's own first write may hold the lock briefly
  ASSERT_EQ(sqlite3_exec(other, "BEGIN EXCLUSIVE", nullptr, nullptr, nullptr), SQLITE_OK);
  // Held for twice a whole cycle and a second: the cycle meets the lock when it stores.
  std::this_thread::sleep_for(2 * cycle_time + std::chrono::seconds(1));
  EXPECT_EQ(core->Status().running_cycle, std::optional<int64_t>(id));
  EXPECT_EQ(core->GetCycle(id)->state, CycleState::kRunning);
  ASSERT_EQ(sqlite3_exec(other, "COMMIT", nullptr, nullptr, nullptr), SQLITE_OK);
  sqlite3_close(other);
  core->WaitIdle();
  absl::StatusOr<StoredCycle> cycle = core->GetCycle(id);
  ASSERT_TRUE(cycle.ok()) << cycle.status();
  EXPECT_EQ(cycle->state, CycleState::kDone);
  EXPECT_EQ(cycle->verdict, Verdict::kError);
  EXPECT_EQ(cycle->reason.rfind("store_unavailable: ", 0), 0u) << cycle->reason;
  EXPECT_NE(cycle->reason.find(config_.db_path), std::string::npos) << cycle->reason;
  EXPECT_TRUE(cycle->sensors.empty());
  const std::vector<StoredEvent> events = *core->store().Events(id);
  ASSERT_FALSE(events.empty());
  EXPECT_EQ(events.back().type, EventType::kCycleEnded);
  EXPECT_EQ(events.back().detail, cycle->reason);
  EXPECT_TRUE(core->store().IntegrityCheck().ok());
}

// A cancel that CancelCycle accepted ends the cycle cancelled wherever it lands (before,
// during or after the sensors are computed); one refused came after the end was decided, and
// that cycle ends done. Replay cycles, cancels after growing delays.
TEST_F(StationCoreTest, AcceptedCancelAlwaysEndsTheCycleCancelled) {
  UseReplay();
  std::unique_ptr<StationCore> core = Core();
  CycleRequest request = Request();
  request.car_model_id = "reference";
  int accepted = 0, refused = 0;
  for (const int delay_ms : {0, 1, 5, 20, 50, 100, 200, 400, 800, 1600}) {
    SCOPED_TRACE(delay_ms);
    const int64_t id = *core->StartCycle(request);
    std::this_thread::sleep_for(std::chrono::milliseconds(delay_ms));
    const absl::Status cancel = core->CancelCycle(id);
    core->WaitIdle();
    const StoredCycle cycle = *core->GetCycle(id);
    if (cancel.ok()) {
      ++accepted;
      EXPECT_EQ(cycle.state, CycleState::kCancelled);
      EXPECT_EQ(cycle.verdict, Verdict::kError);
      EXPECT_EQ(cycle.reason, "cancelled");
    } else {
      ++refused;
      EXPECT_EQ(cancel.code(), absl::StatusCode::kFailedPrecondition) << cancel;
      EXPECT_EQ(cycle.state, CycleState::kDone);
      EXPECT_EQ(cycle.sensors.size(), 2u);
    }
  }
  EXPECT_EQ(accepted + refused, 10);
}

// What kill -9 leaves, rebuilt in the store and on disk: three cycles running, each with a
// capture folder. At the next start they are aborted with an end time, the partial capture of
// the one that did not ask to record is removed, the recorded one stays, and a replayed
// capture (not the cycle's own folder) is never touched. It used to be ended_ns 0 and every
// partial capture kept forever.
TEST_F(StationCoreTest, CyclesAbortedAtStartEndAndLoseTheirPartialCaptures) {
  const fs::path data(config_.data_root);
  std::vector<int64_t> ids;
  {
    absl::StatusOr<std::unique_ptr<Store>> store = Store::Open(config_.db_path);
    ASSERT_TRUE(store.ok()) << store.status();
    const std::pair<bool, std::string> cycles[] = {
        {false, "captures/" + std::string(kVin) + "-100"},
        {true, "captures/" + std::string(kVin) + "-200"},
        {false, "recorded"}};
    int64_t started_ns = 100;
    for (const auto& [record, capture] : cycles) {
      StoredCycle c;
      c.vin = kVin;
      c.car_model_id = "two_sensor";
      c.started_ns = started_ns;
      started_ns += 100;
      c.request_json = nlohmann::json{{"vin", kVin}, {"record_capture", record}}.dump();
      c.capture_path = capture;
      ids.push_back(*(*store)->BeginCycle(c));
      fs::create_directories(data / capture);
      std::ofstream(data / capture / "manifest.json") << "{";  // half written
    }
  }
  std::unique_ptr<StationCore> core = Core();
  ASSERT_NE(core, nullptr);
  EXPECT_EQ(core->store().aborted_at_open(), 3);
  for (int64_t id : ids) {
    const StoredCycle c = *core->GetCycle(id);
    EXPECT_EQ(c.state, CycleState::kAborted) << id;
    EXPECT_GT(c.ended_ns, c.started_ns) << id;
  }
  EXPECT_FALSE(fs::exists(data / "captures" / (std::string(kVin) + "-100")));
  EXPECT_TRUE(fs::exists(data / "captures" / (std::string(kVin) + "-200") / "manifest.json"));
  EXPECT_TRUE(fs::exists(data / "recorded" / "manifest.json"));
}

// One core per database: a second one is refused naming the lock file (Store::Open) and
// leaves the first one's running cycle alone.
TEST_F(StationCoreTest, SecondCoreOnTheSameDatabaseIsRefused) {
  std::unique_ptr<StationCore> core = Core();
  absl::StatusOr<int64_t> id = core->StartCycle(Request());
  ASSERT_TRUE(id.ok()) << id.status();
  const absl::Status second = StationCore::Create(config_).status();
  EXPECT_EQ(second.code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_NE(second.message().find("holds the lock file " + config_.db_path + ".lock"),
            std::string::npos)
      << second;
  core->WaitIdle();
  EXPECT_EQ(core->GetCycle(*id)->state, CycleState::kDone);
}

TEST_F(StationCoreTest, BadConfigurationNamesTheFile) {
  config_.station_path = (dir_ / "missing.json").string();
  const absl::Status s = StationCore::Create(config_).status();
  EXPECT_FALSE(s.ok());
  EXPECT_NE(s.message().find("missing.json"), std::string::npos) << s;
}

}  // namespace
}  // namespace linecal
