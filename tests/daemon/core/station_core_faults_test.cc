// The station core under faults of its storage and its own work (issue 21, items 1, 6 and 7,
// and the budget wiring): a real tmpfs that fills up, a real data root deleted while the core
// runs, a calibration past its deadline on a capture of many frames, a replay capture changed
// after the start. Each test fails on the code before (565161e).
#include <gtest/gtest.h>
#include <sys/mount.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <condition_variable>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <future>
#include <mutex>
#include <nlohmann/json.hpp>
#include <numbers>
#include <string>
#include <thread>

#include "daemon/core/station_core.h"
#include "tests/daemon/reliability/reliability_support.h"
#include "tests/daemon/scratch_dir.h"
#include "tests/daemon/test_car.h"

namespace linecal {
namespace {

namespace fs = std::filesystem;
using std::chrono::milliseconds;
using std::chrono::steady_clock;

const std::string kDeploy = std::string(LINECAL_SOURCE_DIR) + "/deploy";
constexpr char kVin[] = "1M8GDM9AXKP042788";
// How long a test waits for something that must happen (a cycle's end, a watcher's return)
// on a loaded 2-core machine: generous, a hang still fails.
constexpr std::chrono::seconds kPatience{60};

double Seconds(steady_clock::duration d) { return std::chrono::duration<double>(d).count(); }

int TaskCount() {
  int n = 0;
  for (fs::directory_iterator it("/proc/self/task"), end; it != end; ++it) ++n;
  return n;
}

std::vector<std::string> Logged(const std::vector<std::pair<std::string, std::string>>& log) {
  std::vector<std::string> lines;
  for (const auto& [level, message] : log) lines.push_back(level + ": " + message);
  return lines;
}

class StationCoreFaultTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = testing_daemon::FreshTestDir("core_faults");
    testing_daemon::WriteTwoSensorCar((dir_ / "car.json").string(), "two_sensor");
    config_.station_path = kDeploy + "/stations/reference.json";
    config_.car_model_paths = {(dir_ / "car.json").string()};
    config_.db_path = (dir_ / "station.db").string();
    config_.data_root = (dir_ / "data").string();
    config_.log = [this](const LogRecord& record) {
      std::lock_guard<std::mutex> lock(log_mutex_);
      log_.emplace_back(LogLevelName(record.level), record.message);
    };
  }
  void TearDown() override {
    if (!mounted_.empty()) ::umount2(mounted_.c_str(), MNT_DETACH);
    fs::remove_all(dir_);
  }

  // A tmpfs of `bytes` at dir_/tmpfs (root only); false with the reason when it cannot be.
  bool MountTmpfs(std::uint64_t bytes, std::string* why) {
    if (::geteuid() != 0) {
      *why = "mounting a tmpfs needs root";
      return false;
    }
    const fs::path at = dir_ / "tmpfs";
    fs::create_directories(at);
    const std::string options = "size=" + std::to_string(bytes);
    if (::mount("tmpfs", at.c_str(), "tmpfs", 0, options.c_str()) != 0) {
      *why = std::string("mount -t tmpfs: ") + std::strerror(errno);
      return false;
    }
    mounted_ = at.string();
    return true;
  }

  std::unique_ptr<StationCore> Core() {
    absl::StatusOr<std::unique_ptr<StationCore>> core = StationCore::Create(config_);
    EXPECT_TRUE(core.ok()) << core.status();
    return core.ok() ? std::move(*core) : nullptr;
  }

  static CycleRequest Request(const std::string& car = "two_sensor") {
    CycleRequest r;
    r.vin = kVin;
    r.car_model_id = car;
    r.aligner = {0.012, -0.008, 0.05 * std::numbers::pi / 180};
    return r;
  }

  // The replay source on WriteLongCameraCapture(frames) as data_root/long.
  void UseLongReplay(int frames) {
    fs::create_directories(config_.data_root);
    const absl::Status written = reliability::WriteLongCameraCapture(
        (fs::path(config_.data_root) / "long").string(), frames);
    ASSERT_TRUE(written.ok()) << written;
    config_.source = CycleSource::kReplay;
    config_.replay_capture = "long";
    config_.car_model_paths = {kDeploy + "/cars/reference.json"};
  }

  // Runs WatchCycle on its own thread; the future has its status and the last event type.
  static std::future<std::pair<absl::Status, std::string>> Watch(StationCore& core, int64_t id) {
    return std::async(std::launch::async, [&core, id] {
      std::string last;
      const absl::Status s = core.WatchCycle(id, [&](const StoredEvent& e) {
        last = EventTypeName(e.type) + std::string("/") + e.detail;
        return true;
      });
      return std::make_pair(s, last);
    });
  }

  bool LogHas(const std::string& level, const std::string& text) {
    std::lock_guard<std::mutex> lock(log_mutex_);
    for (const auto& [l, m] : log_) {
      if (l == level && m.find(text) != std::string::npos) return true;
    }
    return false;
  }

  fs::path dir_;
  std::string mounted_;
  StationCoreConfig config_;
  std::mutex log_mutex_;
  std::vector<std::pair<std::string, std::string>> log_;
};

// A live source that waits at Acquire until the test lets it go, then fails: the cycle is
// held after its start (stored) and before it writes its capture.
class GateSource : public SensorSource {
 public:
  struct Gate {
    std::mutex mutex;
    std::condition_variable changed;
    int entered = 0;
    bool open = false;
  };
  explicit GateSource(std::shared_ptr<Gate> gate) : gate_(std::move(gate)) {}
  absl::StatusOr<CaptureSensor> Acquire(const SensorModel&, const AcquireRequest&) override {
    std::unique_lock<std::mutex> lock(gate_->mutex);
    ++gate_->entered;
    gate_->changed.notify_all();
    gate_->changed.wait(lock, [&] { return gate_->open; });
    return absl::UnavailableError("gate: no device");
  }
  std::string Describe() const override { return "gate"; }

 private:
  std::shared_ptr<Gate> gate_;
};

// Issue 21, item 1: with the database on a full tmpfs, the cycle that met the limit stayed
// `running` forever, the station said idle, WatchCycle never returned, and the next cycle ran
// beside it. Now it ends in error naming the full disk, the watcher returns, Health() is
// NOT_SERVING and a new cycle is refused; once space returns the end is stored and the
// station serves again, without a restart.
TEST_F(StationCoreFaultTest, DiskFullMidCycleEndsInErrorAndRecoversWhenSpaceReturns) {
  std::string why;
  // 24 MiB: the database and a cycle fit, and freeing the filler leaves more than
  // kFreeBytesToServe (16 MiB) free.
  if (!MountTmpfs(24u << 20, &why)) GTEST_SKIP() << why;
  config_.data_root = mounted_ + "/data";
  config_.db_path = mounted_ + "/data/station.db";
  config_.source = CycleSource::kLive;
  auto gate = std::make_shared<GateSource::Gate>();
  SourceConfig camera;
  camera.type = SourceType::kAravis;
  camera.aravis.device_id = "gate";
  SourceConfig radar;
  radar.type = SourceType::kCandump;
  radar.can.log_path = "/dev/null";
  config_.live_sources = {{"front_camera", camera}, {"front_radar", radar}};
  config_.make_source = [gate](
                            const std::string&,
                            const SourceConfig&) -> absl::StatusOr<std::unique_ptr<SensorSource>> {
    return std::make_unique<GateSource>(gate);
  };
  std::unique_ptr<StationCore> core = Core();
  ASSERT_NE(core, nullptr);
  ASSERT_TRUE(core->Health().ok());

  const absl::StatusOr<int64_t> id = core->StartCycle(Request());
  ASSERT_TRUE(id.ok()) << id.status();
  {
    std::unique_lock<std::mutex> lock(gate->mutex);
    ASSERT_TRUE(gate->changed.wait_for(lock, kPatience, [&] { return gate->entered == 2; }));
  }
  // Fill the file system to the last byte while the cycle is held.
  const fs::path filler = fs::path(mounted_) / "filler";
  ASSERT_GT(reliability::FillFileSystem(filler.string()), 0u);
  auto watcher = Watch(*core, *id);
  {
    std::lock_guard<std::mutex> lock(gate->mutex);
    gate->open = true;
  }
  gate->changed.notify_all();

  ASSERT_EQ(watcher.wait_for(kPatience), std::future_status::ready) << "WatchCycle never ended";
  const auto [watch_status, last_event] = watcher.get();
  EXPECT_TRUE(watch_status.ok()) << watch_status;
  EXPECT_EQ(last_event.rfind("cycle_ended/disk_full: ", 0), 0u) << last_event;
  EXPECT_EQ(core->Status().running_cycle, std::nullopt);
  const StoredCycle shown = *core->GetCycle(*id);
  EXPECT_EQ(shown.state, CycleState::kDone);
  EXPECT_EQ(shown.verdict, Verdict::kError);
  EXPECT_EQ(shown.reason.rfind("disk_full: ", 0), 0u) << shown.reason;
  EXPECT_NE(shown.reason.find("No space left on device"), std::string::npos) << shown.reason;
  EXPECT_GT(shown.ended_ns, shown.started_ns);
  EXPECT_TRUE(LogHas("error", "cycle " + std::to_string(*id) + " ended done (disk_full: "))
      << testing::PrintToString(Logged(log_));

  const absl::Status health = core->Health();
  EXPECT_EQ(health.code(), absl::StatusCode::kResourceExhausted) << health;
  EXPECT_NE(health.message().find("database or disk is full"), std::string::npos) << health;
  // No second cycle beside the unstored one.
  const absl::Status refused = core->StartCycle(Request()).status();
  EXPECT_EQ(refused.code(), absl::StatusCode::kResourceExhausted) << refused;
  EXPECT_NE(refused.message().find("cycle " + std::to_string(*id) + "'s end is not stored yet"),
            std::string::npos)
      << refused;

  // Space returns: the next health check stores the end, and the station serves again.
  fs::remove(filler);
  const absl::Status back = core->Health();
  EXPECT_TRUE(back.ok()) << back;
  EXPECT_TRUE(LogHas("warning", "health: serving again"));
  const StoredCycle stored = *core->store().GetCycle(*id);
  EXPECT_EQ(stored.state, CycleState::kDone);
  EXPECT_EQ(stored.verdict, Verdict::kError);
  EXPECT_EQ(stored.reason, shown.reason);
  EXPECT_EQ(stored.ended_ns, shown.ended_ns);
  const std::vector<StoredEvent> events = *core->store().Events(*id);
  ASSERT_FALSE(events.empty());
  EXPECT_EQ(events.back().type, EventType::kCycleEnded);
  EXPECT_EQ(events.back().detail, shown.reason);
  EXPECT_EQ(*core->store().RunningCycle(), std::nullopt);
  EXPECT_TRUE(core->store().IntegrityCheck().ok());
  const absl::StatusOr<int64_t> next = core->StartCycle(Request());
  ASSERT_TRUE(next.ok()) << next.status();
  core->WaitIdle();
  EXPECT_EQ(core->GetCycle(*next)->state, CycleState::kDone);
}

// Issue 21, item 7: the data folder (database included) deleted while the daemon ran: cycles
// reported done/pass into a database file that no longer existed, and a restart listed none.
// Now the cycle that meets it ends in error naming the data root, the log says so, Health()
// is NOT_SERVING, and new cycles are refused.
TEST_F(StationCoreFaultTest, DataRootDeletedWhileRunningEndsTheCycleInError) {
  // A replay of 20 frames (seconds of detections): nothing writes into the data root while
  // it is removed, and the cycle is still calibrating when it is.
  UseLongReplay(20);
  config_.db_path = (fs::path(config_.data_root) / "station.db").string();
  std::unique_ptr<StationCore> core = Core();
  ASSERT_NE(core, nullptr);
  ASSERT_TRUE(core->Health().ok());

  const absl::StatusOr<int64_t> id = core->StartCycle(Request("reference"));
  ASSERT_TRUE(id.ok()) << id.status();
  // Half a second: the capture read, the calibration under way.
  std::this_thread::sleep_for(milliseconds(500));
  std::error_code ec;
  fs::remove_all(config_.data_root, ec);  // as `rm -rf` would, while the cycle runs
  ASSERT_FALSE(ec) << ec.message();
  EXPECT_EQ(core->Status().running_cycle, std::optional<int64_t>(*id));
  core->WaitIdle();
  const StoredCycle cycle = *core->GetCycle(*id);
  EXPECT_EQ(cycle.verdict, Verdict::kError);
  const std::string removed =
      "data_root_removed: data_root '" + config_.data_root + "' was removed";
  EXPECT_EQ(cycle.reason.rfind(removed, 0), 0u) << cycle.reason;
  EXPECT_TRUE(LogHas("error", "cycle " + std::to_string(*id) + " ended"))
      << testing::PrintToString(Logged(log_));
  const absl::Status health = core->Health();
  EXPECT_EQ(health.code(), absl::StatusCode::kFailedPrecondition) << health;
  EXPECT_NE(health.message().find(config_.data_root), std::string::npos) << health;
  EXPECT_TRUE(LogHas("error", "health: NOT_SERVING: data_root '" + config_.data_root));
  const absl::Status refused = core->StartCycle(Request("reference")).status();
  EXPECT_EQ(refused.code(), absl::StatusCode::kFailedPrecondition) << refused;
  EXPECT_NE(refused.message().find("data_root '" + config_.data_root + "' was removed"),
            std::string::npos)
      << refused;
}

// The database file alone deleted (the data root stays): the same, named by the store.
TEST_F(StationCoreFaultTest, DatabaseFileDeletedIsNotServing) {
  std::unique_ptr<StationCore> core = Core();
  ASSERT_NE(core, nullptr);
  ASSERT_TRUE(core->Health().ok());
  fs::remove(config_.db_path);
  const absl::Status health = core->Health();
  EXPECT_EQ(health.code(), absl::StatusCode::kFailedPrecondition) << health;
  EXPECT_NE(health.message().find("database " + config_.db_path + ": the file was removed"),
            std::string::npos)
      << health;
  EXPECT_EQ(core->StartCycle(Request()).status().code(), absl::StatusCode::kFailedPrecondition);
}

// Issue 21, item 6: a calibration past its deadline ran on, abandoned, on its threads (12 ->
// 29 threads after three such cycles, a core busy while idle). Now it is stopped: the threads
// are back to the count before the cycle within 1 s of its end.
TEST_F(StationCoreFaultTest, DeadlineHitCycleFreesItsThreadsWithinOneSecond) {
  // 600 frames: a minute of detections at least; 300 ms: the first few of them.
  UseLongReplay(600);
  config_.calibrate_deadline = milliseconds(300);
  std::unique_ptr<StationCore> core = Core();
  ASSERT_NE(core, nullptr);
  const int baseline = TaskCount();
  const auto start = steady_clock::now();
  const int64_t id = *core->StartCycle(Request("reference"));
  core->WaitIdle();
  const auto ended = steady_clock::now();
  const StoredCycle cycle = *core->GetCycle(id);
  EXPECT_EQ(cycle.state, CycleState::kDone);
  EXPECT_EQ(cycle.verdict, Verdict::kError);
  EXPECT_EQ(cycle.reason, "calibrate_deadline_exceeded");
  // The end waits at most for the stop (kCalibrationStopGrace) after the deadline; 10 s of
  // slack for reading the capture on a loaded machine.
  EXPECT_LT(Seconds(ended - start), 10.0);
  while (TaskCount() > baseline && steady_clock::now() - ended < std::chrono::seconds(5)) {
    std::this_thread::sleep_for(milliseconds(10));
  }
  EXPECT_LE(TaskCount(), baseline);
  EXPECT_LE(Seconds(steady_clock::now() - ended), 1.0) << "threads freed late";
  EXPECT_FALSE(LogHas("warning", "a stopped calibration still runs"));
}

// A cancel stops the calibration too: the cycle ends cancelled and its threads are gone.
TEST_F(StationCoreFaultTest, CancelStopsTheCalibration) {
  UseLongReplay(600);
  std::unique_ptr<StationCore> core = Core();
  ASSERT_NE(core, nullptr);
  const int baseline = TaskCount();
  const int64_t id = *core->StartCycle(Request("reference"));
  // Half a second: the capture read, the calibration under way.
  std::this_thread::sleep_for(milliseconds(500));
  ASSERT_TRUE(core->CancelCycle(id).ok());
  const auto cancelled = steady_clock::now();
  core->WaitIdle();
  EXPECT_EQ(core->GetCycle(id)->state, CycleState::kCancelled);
  while (TaskCount() > baseline && steady_clock::now() - cancelled < std::chrono::seconds(5)) {
    std::this_thread::sleep_for(milliseconds(10));
  }
  EXPECT_LE(TaskCount(), baseline);
  // The cancel is seen within 50 ms, the stop within a frame's detection.
  EXPECT_LE(Seconds(steady_clock::now() - cancelled), 1.5);
}

// The budget of the configuration applies to the replayed capture at every cycle: a manifest
// grown past max_manifest_frames after the start is refused (it used to be read with the
// default budget of 1000 frames).
TEST_F(StationCoreFaultTest, ReplayCycleReadsTheCaptureUnderTheConfiguredBudget) {
  UseLongReplay(3);
  config_.input_budget.max_manifest_frames = 3;
  std::unique_ptr<StationCore> core = Core();
  ASSERT_NE(core, nullptr);
  // The capture grows to 5 frames.
  const fs::path capture = fs::path(config_.data_root) / "long";
  std::ifstream in(capture / "manifest.json");
  nlohmann::json manifest = nlohmann::json::parse(in);
  in.close();
  nlohmann::json& frames = manifest["sensors"][0]["frames"];
  frames.push_back(frames[0]);
  frames.push_back(frames[1]);
  std::ofstream(capture / "manifest.json") << manifest.dump(2);
  const int64_t id = *core->StartCycle(Request("reference"));
  core->WaitIdle();
  const StoredCycle cycle = *core->GetCycle(id);
  EXPECT_EQ(cycle.verdict, Verdict::kError);
  EXPECT_EQ(cycle.reason.rfind("capture_unreadable: ", 0), 0u) << cycle.reason;
  EXPECT_NE(cycle.reason.find("5 frames exceed the budget of 3 (input_budget.max_manifest_frames)"),
            std::string::npos)
      << cycle.reason;

  // And at the start: the same capture is refused by Create.
  core.reset();
  const absl::Status refused = StationCore::Create(config_).status();
  EXPECT_NE(refused.message().find("input_budget.max_manifest_frames"), std::string::npos)
      << refused;
}

// The replay folder replaced by a link out of the data root after the start: the next cycle
// refuses it (Create checked it only once; the cycle used to read the linked capture).
TEST_F(StationCoreFaultTest, ReplayFolderLinkedOutsideAfterTheStartIsRefused) {
  UseLongReplay(1);
  std::unique_ptr<StationCore> core = Core();
  ASSERT_NE(core, nullptr);
  const fs::path capture = fs::path(config_.data_root) / "long";
  const fs::path outside = dir_ / "outside";
  fs::rename(capture, outside);
  fs::create_directory_symlink(outside, capture);
  const int64_t id = *core->StartCycle(Request("reference"));
  core->WaitIdle();
  const StoredCycle cycle = *core->GetCycle(id);
  EXPECT_EQ(cycle.verdict, Verdict::kError);
  EXPECT_EQ(cycle.reason, "capture_unreadable: source.capture: 'long': resolves outside data_root")
      << cycle.reason;
  EXPECT_TRUE(cycle.sensors.empty());
}

}  // namespace
}  // namespace linecal
