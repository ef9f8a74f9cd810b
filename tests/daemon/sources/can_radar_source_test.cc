// The CAN radar source: candump logs written by the simulator (station/sim) replayed into a
// scratch capture, and SocketCAN — whose opening fails for real on this kernel (no CAN), and
// whose reading is exercised through a socket pair standing in for the CAN socket
// (socketcan.h's SocketCanSyscalls), fed kernel frames by a thread.
#include "daemon/sources/can_radar_source.h"

#include <gtest/gtest.h>
#include <linux/can.h>
#include <net/if.h>
#include <net/if_arp.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "station/io/candump.h"
#include "station/sim/simulator.h"

namespace linecal {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;
const std::string kDeploy = std::string(LINECAL_SOURCE_DIR) + "/deploy";

class CanRadarSourceTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::path(testing::TempDir()) /
           ("can_src_" + std::to_string(::getpid()) + "_" +
            testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_ / "capture");
    car_ = *ReadCarModel(kDeploy + "/cars/reference.json");
  }
  void TearDown() override { fs::remove_all(dir_); }

  // The simulator's capture of the front ARS408 and the left corner ESR; returns their logs.
  std::pair<std::vector<CanFrame>, std::vector<CanFrame>> SimulatedLogs() {
    SimulatorOptions o;
    o.sensors = {"front_radar", "corner_radar_left"};
    o.time_ns = 1'700'000'000'000'000'000;
    EXPECT_TRUE(SimulateCapture(*ReadStationLayout(kDeploy + "/stations/reference.json"), car_, o,
                                5, (dir_ / "sim").string())
                    .ok());
    return {*ReadCandumpLog(dir_ / "sim/front_radar/can.log"),
            *ReadCandumpLog(dir_ / "sim/corner_radar_left/can.log")};
  }

  AcquireRequest Request(
      std::chrono::milliseconds deadline = std::chrono::milliseconds(5000)) const {
    AcquireRequest r;
    r.capture_dir = (dir_ / "capture").string();
    r.sensor_dir = "radar";
    r.deadline = Clock::now() + deadline;
    return r;
  }

  static CanRadarSourceConfig LogConfig(const fs::path& log) {
    CanRadarSourceConfig c;
    c.input = CanRadarSourceConfig::Input::kCandumpLog;
    c.log_path = log.string();
    return c;
  }

  const SensorModel& Sensor(const std::string& name) const { return *car_.FindSensor(name); }

  fs::path dir_;
  CarModel car_;
};

TEST_F(CanRadarSourceTest, SimulatorLogGivesTheSameFrames) {
  const std::vector<CanFrame> front = SimulatedLogs().first;
  ASSERT_GT(front.size(), 100u);
  CanRadarSource source(LogConfig(dir_ / "sim/front_radar/can.log"));
  std::vector<std::string> progress;
  AcquireRequest request = Request();
  request.progress = [&](const std::string& d) { progress.push_back(d); };
  absl::StatusOr<CaptureSensor> got = source.Acquire(Sensor("front_radar"), request);
  ASSERT_TRUE(got.ok()) << got.status();
  EXPECT_EQ(got->name, "front_radar");
  EXPECT_EQ(got->kind, SensorKind::kRadar);
  ASSERT_TRUE(got->can_log.has_value());
  EXPECT_EQ(got->can_log->path, "radar/can.log");
  EXPECT_EQ(got->can_log->t_ns,
            std::chrono::duration_cast<std::chrono::nanoseconds>(front[0].time.time_since_epoch())
                .count());
  EXPECT_EQ(*ReadCandumpLog(dir_ / "capture/radar/can.log"), front);
  // The simulator's default: 20 ARS408 cycles.
  ASSERT_EQ(progress.size(), 1u);
  EXPECT_EQ(progress[0], absl::StrCat(front.size(), " frames, 20 radar cycles (0 incomplete)"));
}

TEST_F(CanRadarSourceTest, AMixedLogGivesEachRadarItsOwnFrames) {
  const auto [front, corner] = SimulatedLogs();
  std::vector<CanFrame> mixed = front;
  mixed.insert(mixed.end(), corner.begin(), corner.end());
  std::stable_sort(mixed.begin(), mixed.end(),
                   [](const CanFrame& a, const CanFrame& b) { return a.time < b.time; });
  ASSERT_TRUE(WriteCandumpLog(dir_ / "bus.log", mixed).ok());
  CanRadarSource source(LogConfig(dir_ / "bus.log"));
  ASSERT_TRUE(source.Acquire(Sensor("front_radar"), Request()).ok());
  EXPECT_EQ(*ReadCandumpLog(dir_ / "capture/radar/can.log"), front);
  ASSERT_TRUE(source.Acquire(Sensor("corner_radar_left"), Request()).ok());
  EXPECT_EQ(*ReadCandumpLog(dir_ / "capture/radar/can.log"), corner);
  // Another interface's frames are left out when the source names its interface.
  CanRadarSourceConfig can1 = LogConfig(dir_ / "bus.log");
  can1.interface = "can1";
  absl::StatusOr<CaptureSensor> none =
      CanRadarSource(can1).Acquire(Sensor("front_radar"), Request());
  EXPECT_TRUE(absl::IsDataLoss(none.status())) << none.status();
  EXPECT_NE(none.status().message().find("on can1"), std::string::npos) << none.status();
}

TEST_F(CanRadarSourceTest, RecordTimeSelectsTheStartOfTheLog) {
  const std::vector<CanFrame> front = SimulatedLogs().first;
  CanRadarSourceConfig c = LogConfig(dir_ / "sim/front_radar/can.log");
  c.record = std::chrono::milliseconds(500);
  ASSERT_TRUE(CanRadarSource(c).Acquire(Sensor("front_radar"), Request()).ok());
  std::vector<CanFrame> expected;
  for (const CanFrame& f : front) {
    if (f.time - front[0].time < std::chrono::milliseconds(500)) expected.push_back(f);
  }
  ASSERT_LT(expected.size(), front.size());
  EXPECT_EQ(*ReadCandumpLog(dir_ / "capture/radar/can.log"), expected);
}

TEST_F(CanRadarSourceTest, ALogWithoutThisRadarIsDataLoss) {
  const std::vector<CanFrame> corner = SimulatedLogs().second;
  CanRadarSource source(LogConfig(dir_ / "sim/corner_radar_left/can.log"));
  absl::StatusOr<CaptureSensor> got = source.Acquire(Sensor("front_radar"), Request());
  ASSERT_TRUE(absl::IsDataLoss(got.status())) << got.status();
  EXPECT_EQ(
      got.status().message(),
      absl::StrCat("front_radar: candump log '", (dir_ / "sim/corner_radar_left/can.log").string(),
                   "' has no frame of ars408 sensor id 0 (", corner.size(),
                   " frames in all): the radar was silent"));
  std::ofstream(dir_ / "empty.log").flush();
  got = CanRadarSource(LogConfig(dir_ / "empty.log")).Acquire(Sensor("front_radar"), Request());
  EXPECT_TRUE(absl::IsDataLoss(got.status())) << got.status();
  EXPECT_NE(got.status().message().find("(0 frames in all)"), std::string::npos) << got.status();
  EXPECT_FALSE(fs::exists(dir_ / "capture/radar/can.log"));
}

TEST_F(CanRadarSourceTest, MissingOrBrokenLogsNameTheFile) {
  absl::StatusOr<CaptureSensor> got =
      CanRadarSource(LogConfig(dir_ / "nope.log")).Acquire(Sensor("front_radar"), Request());
  EXPECT_TRUE(absl::IsUnavailable(got.status())) << got.status();
  EXPECT_NE(got.status().message().find("nope.log"), std::string::npos) << got.status();
  std::ofstream(dir_ / "bad.log") << "(1700000000.000000) can0 600#00\nnot a frame\n";
  got = CanRadarSource(LogConfig(dir_ / "bad.log")).Acquire(Sensor("front_radar"), Request());
  EXPECT_TRUE(absl::IsDataLoss(got.status())) << got.status();
  EXPECT_NE(got.status().message().find("bad.log:2"), std::string::npos) << got.status();
}

TEST_F(CanRadarSourceTest, WrongKindIsInvalidArgument) {
  CanRadarSource source(LogConfig(dir_ / "x.log"));
  EXPECT_TRUE(absl::IsInvalidArgument(source.Acquire(Sensor("roof_lidar"), Request()).status()));
  EXPECT_EQ(source.Describe(), "candump " + (dir_ / "x.log").string());
}

CanRadarSourceConfig BusConfig(const std::string& interface) {
  CanRadarSourceConfig c;
  c.input = CanRadarSourceConfig::Input::kSocketCan;
  c.interface = interface;
  return c;
}

// This kernel has no CAN: the real socket(PF_CAN) fails, and the error names the interface.
TEST_F(CanRadarSourceTest, SocketCanWithoutKernelSupportNamesTheInterface) {
  const int probe = ::socket(PF_CAN, SOCK_RAW, CAN_RAW);
  if (probe >= 0) {
    ::close(probe);
    GTEST_SKIP() << "this kernel has CAN";
  }
  absl::StatusOr<CaptureSensor> got =
      CanRadarSource(BusConfig("can0")).Acquire(Sensor("front_radar"), Request());
  ASSERT_TRUE(absl::IsFailedPrecondition(got.status())) << got.status();
  EXPECT_EQ(
      got.status().message().rfind("front_radar: SocketCAN can0: kernel has no CAN support", 0), 0u)
      << got.status();
}

// The descriptor the stand-in socket() hands Open next (Open takes ownership).
int g_next_socket = -1;
int StandInSocket(int, int, int) { return std::exchange(g_next_socket, -1); }

TEST_F(CanRadarSourceTest, SocketCanMissingInterfaceIsUnavailableNamingIt) {
  // Past socket(PF_CAN) with an inet socket; the real if_nametoindex finds no "can9".
  SocketCanSyscalls sys = SocketCanSyscalls::Real();
  sys.socket = StandInSocket;
  g_next_socket = ::socket(AF_INET, SOCK_DGRAM, 0);
  absl::StatusOr<CaptureSensor> got =
      CanRadarSource(BusConfig("can9"), sys).Acquire(Sensor("front_radar"), Request());
  ASSERT_TRUE(absl::IsUnavailable(got.status())) << got.status();
  EXPECT_EQ(got.status().message(),
            "front_radar: SocketCAN can9: no such interface (ip link lists the interfaces)");
}

// A CAN interface that is up, for Open; reading uses the real calls on the socket pair.
int IoctlUpCan(int, unsigned long request, void* arg) {
  ifreq* req = static_cast<ifreq*>(arg);
  if (request == SIOCGIFFLAGS) req->ifr_flags = IFF_UP | IFF_RUNNING;
  if (request == SIOCGIFHWADDR) req->ifr_hwaddr.sa_family = ARPHRD_CAN;
  return 0;
}
unsigned IndexSeven(const char*) { return 7; }
int SetsockoptOk(int, int, int, const void*, socklen_t) { return 0; }
int BindOk(int, const sockaddr*, socklen_t) { return 0; }

class SocketPairBus {
 public:
  SocketPairBus() {
    int pair[2];
    EXPECT_EQ(::socketpair(AF_UNIX, SOCK_DGRAM, 0, pair), 0);
    g_next_socket = pair[0];
    writer_ = pair[1];
  }
  ~SocketPairBus() {
    if (thread_.joinable()) thread_.join();
    ::close(writer_);
  }
  SocketCanSyscalls syscalls() const {
    return {StandInSocket, IndexSeven, IoctlUpCan, SetsockoptOk, BindOk};
  }
  // Sends the frames as the kernel would deliver them, after `delay`, 200 us apart; the time
  // frame `marked` went out is kept for sent_at().
  void SendLater(std::vector<CanFrame> frames, std::chrono::milliseconds delay,
                 std::size_t marked = 0) {
    thread_ = std::thread([this, frames = std::move(frames), delay, marked] {
      std::this_thread::sleep_for(delay);
      for (std::size_t i = 0; i < frames.size(); ++i) {
        const CanFrame& f = frames[i];
        if (i == marked) marked_at_ = std::chrono::steady_clock::now();
        can_frame k{};
        k.can_id = f.id;
        k.len = f.len;
        std::memcpy(k.data, f.data.data(), f.len);
        ::send(writer_, &k, CAN_MTU, 0);
        std::this_thread::sleep_for(std::chrono::microseconds(200));
      }
    });
  }
  // When the marked frame was sent; valid once the sender is done (Join).
  std::chrono::steady_clock::time_point sent_at() const { return marked_at_; }
  void Join() {
    if (thread_.joinable()) thread_.join();
  }

 private:
  int writer_ = -1;
  std::thread thread_;
  std::chrono::steady_clock::time_point marked_at_;
};

TEST_F(CanRadarSourceTest, SocketCanRecordsThisRadarsFramesForTheRecordTime) {
  const auto [front, corner] = SimulatedLogs();
  std::vector<CanFrame> bus;  // the corner radar's frames first, then the front radar's
  bus.insert(bus.end(), corner.begin(), corner.begin() + 200);
  bus.insert(bus.end(), front.begin(), front.end());
  SocketPairBus pair;
  CanRadarSourceConfig c = BusConfig("can7");
  c.record = std::chrono::milliseconds(3000);
  CanRadarSource source(c, pair.syscalls());
  pair.SendLater(bus, std::chrono::milliseconds(100), /*marked=*/200);
  absl::StatusOr<CaptureSensor> got = source.Acquire(Sensor("front_radar"), Request());
  const auto end = Clock::now();
  pair.Join();
  ASSERT_TRUE(got.ok()) << got.status();
  // Recording ends the record time after the first front radar frame (measured from when it
  // was sent, so that a loaded machine's late sender does not move the bound).
  const double recorded_s = std::chrono::duration<double>(end - pair.sent_at()).count();
  EXPECT_GT(recorded_s, 3.0);
  EXPECT_LT(recorded_s, 3.4);
  const std::vector<CanFrame> recorded = *ReadCandumpLog(dir_ / "capture/radar/can.log");
  ASSERT_EQ(recorded.size(), front.size());
  for (size_t i = 0; i < front.size(); ++i) {
    EXPECT_EQ(recorded[i].interface, "can7");
    EXPECT_EQ(recorded[i].id, front[i].id) << i;
    EXPECT_EQ(recorded[i].data, front[i].data) << i;
  }
}

TEST_F(CanRadarSourceTest, SilentSocketCanIsDeadlineExceeded) {
  const std::vector<CanFrame> corner = SimulatedLogs().second;
  SocketPairBus pair;
  CanRadarSource source(BusConfig("can7"), pair.syscalls());
  pair.SendLater({corner.begin(), corner.begin() + 50}, std::chrono::milliseconds(0));
  const auto start = Clock::now();
  absl::StatusOr<CaptureSensor> got =
      source.Acquire(Sensor("front_radar"), Request(std::chrono::milliseconds(1000)));
  const double elapsed = std::chrono::duration<double>(Clock::now() - start).count();
  ASSERT_TRUE(absl::IsDeadlineExceeded(got.status())) << got.status();
  EXPECT_EQ(got.status().message(),
            "front_radar: no frame of ars408 sensor id 0 on can7 in 1.0 s (50 other frames): the "
            "radar is silent");
  EXPECT_LT(elapsed, 1.5);
}

TEST_F(CanRadarSourceTest, CancelStopsSocketCanPromptly) {
  SocketPairBus pair;
  CanRadarSource source(BusConfig("can7"), pair.syscalls());
  std::atomic<bool> cancel{false};
  AcquireRequest request = Request();
  request.cancel = &cancel;
  std::thread canceller([&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
    cancel = true;
  });
  const auto start = Clock::now();
  absl::StatusOr<CaptureSensor> got = source.Acquire(Sensor("front_radar"), request);
  canceller.join();
  EXPECT_TRUE(absl::IsCancelled(got.status())) << got.status();
  EXPECT_LT(std::chrono::duration<double>(Clock::now() - start).count(), 0.4);
}

TEST(CanRadarSourceConfigTest, ValidateNamesTheField) {
  CanRadarSourceConfig c;
  c.input = CanRadarSourceConfig::Input::kSocketCan;
  EXPECT_EQ(c.Validate().message(), "interface: '' must have 1..15 characters");
  c.interface = "can0";
  c.record = std::chrono::milliseconds(0);
  EXPECT_EQ(c.Validate().message(), "record_ms: 0 must be in [1, 60000]");
  c.input = CanRadarSourceConfig::Input::kCandumpLog;
  c.record = std::chrono::milliseconds(100);
  EXPECT_EQ(c.Validate().message(), "log: empty");
}

}  // namespace
}  // namespace linecal
