// End to end through the real processes on loopback: `linecal sim` renders a car, `linecal
// serve-sensors` serves it as live sensors (a fake GigE Vision camera through Aravis, the
// LiDAR's packets over UDP, the radar's candump log), `linecald` runs a cycle on them from
// the configuration serve-sensors wrote, the client starts it and waits; the recorded capture
// recomputed offline by `linecal calibrate` must give the same results as the daemon stored.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <regex>
#include <sstream>
#include <string>
#include <thread>

#include "tests/daemon/test_car.h"
#include "tests/tools/run_linecal.h"

namespace linecal {
namespace {

namespace fs = std::filesystem;
using testing_tools::LinecalRun;
using testing_tools::RunLinecal;

const std::string kVin = "1M8GDM9AXKP042788";

std::string ReadText(const fs::path& p) {
  std::ifstream f(p);
  std::stringstream text;
  text << f.rdbuf();
  return text.str();
}

// A child process running `binary args...` with stderr into `log`.
pid_t Spawn(const std::string& binary, const std::vector<std::string>& args, const fs::path& log) {
  const pid_t pid = ::fork();
  if (pid == 0) {
    FILE* err = std::freopen(log.c_str(), "w", stderr);
    (void)err;
    std::vector<char*> argv;
    argv.push_back(const_cast<char*>(binary.c_str()));
    for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);
    ::execv(binary.c_str(), argv.data());
    ::_exit(127);
  }
  return pid;
}

// SIGTERM, then the exit status; true when it exited 0.
bool Stop(pid_t pid) {
  if (pid <= 0) return true;
  ::kill(pid, SIGTERM);
  int status = 0;
  ::waitpid(pid, &status, 0);
  return WIFEXITED(status) && WEXITSTATUS(status) == 0;
}

class LiveCycleTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::path(testing::TempDir()) / ("live_cycle_" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    testing_daemon::WriteCutDownCar((dir_ / "car.json").string(),
                                    {"front_camera", "bumper_lidar", "front_radar"});
    // The aligner bounds 0: the simulated car stands where the cycle request says (at 0).
    const LinecalRun sim =
        RunLinecal("sim --station " + std::string(LINECAL_SOURCE_DIR) +
                   "/deploy/stations/reference.json --car " + (dir_ / "car.json").string() +
                   " --out " + (dir_ / "sensors").string() +
                   " --seed 5 --aligner-offset-m 0 --aligner-thrust-deg 0 --lidar-rotations 2");
    ASSERT_EQ(sim.exit_code, 0) << sim.err;
  }
  void TearDown() override {
    EXPECT_TRUE(Stop(daemon_)) << "linecald did not stop cleanly on SIGTERM";
    EXPECT_TRUE(Stop(server_)) << "serve-sensors did not stop cleanly on SIGTERM";
    fs::remove_all(dir_);
  }

  // Starts the sensor server (extra options) and linecald on its configuration; the client's
  // connection flags in connection_.
  void Start(const std::string& extra_option = "") {
    std::vector<std::string> args = {"serve-sensors", "--capture", (dir_ / "sensors").string(),
                                     "--write-config", (dir_ / "linecald.json").string(),
                                     "--data-root", (dir_ / "data").string(),
                                     // A port per test process: ctest runs tests in parallel.
                                     "--lidar-port", std::to_string(20000 + ::getpid() % 20000)};
    if (!extra_option.empty()) {
      args.push_back("--lost-ratio");
      args.push_back(extra_option);
    }
    fs::create_directories(dir_ / "data");
    server_ = Spawn(std::string(LINECAL_BINARY_DIR) + "/bin/linecal", args, dir_ / "sensors.log");
    for (int i = 0; i < 200 && !fs::exists(dir_ / "linecald.json"); ++i) {
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    ASSERT_TRUE(fs::exists(dir_ / "linecald.json")) << ReadText(dir_ / "sensors.log");
    daemon_ = Spawn(std::string(LINECAL_BINARY_DIR) + "/bin/linecald",
                    {"--config", (dir_ / "linecald.json").string(), "--listen", "127.0.0.1:0"},
                    dir_ / "linecald.log");
    const std::regex port_re("\\(port ([0-9]+)\\)");
    std::string port;
    for (int i = 0; i < 200 && port.empty(); ++i) {
      std::smatch m;
      const std::string log = ReadText(dir_ / "linecald.log");
      if (std::regex_search(log, m, port_re)) port = m[1];
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    ASSERT_FALSE(port.empty()) << "linecald did not start: " << ReadText(dir_ / "linecald.log");
    connection_ = " --address 127.0.0.1:" + port;
  }

  // Runs one cycle with --record and two frames per sensor (two LiDAR rotations keep the
  // bumper LiDAR's sigma inside its bar) and returns the stored cycle.
  nlohmann::json RunCycle() {
    const LinecalRun start =
        RunLinecal("cycle start --vin " + kVin +
                   " --car reference --record --frames 2 --wait --json" + connection_);
    EXPECT_TRUE(start.exit_code == 0 || start.exit_code == 1) << start.out << start.err;
    return start.out.empty() ? nlohmann::json() : nlohmann::json::parse(start.out);
  }

  std::map<std::string, nlohmann::json> BySensor(const nlohmann::json& sensors,
                                                 const char* name_key) {
    std::map<std::string, nlohmann::json> out;
    for (const nlohmann::json& s : sensors) out[s[name_key].get<std::string>()] = s;
    return out;
  }

  fs::path dir_;
  pid_t server_ = -1;
  pid_t daemon_ = -1;
  std::string connection_;
};

TEST_F(LiveCycleTest, LiveSensorsGiveTheOfflineResultsOfTheirRecording) {
  ASSERT_NO_FATAL_FAILURE(Start());
  const nlohmann::json cycle = RunCycle();
  ASSERT_FALSE(cycle.is_null());
  EXPECT_EQ(cycle["state"], "CYCLE_STATE_DONE");
  const std::map<std::string, nlohmann::json> live = BySensor(cycle["sensors"], "name");
  ASSERT_EQ(live.size(), 3u);
  // Every sensor acquired and calibrated from the wire: none in error.
  for (const auto& [name, s] : live)
    EXPECT_EQ(s["verdict"], "VERDICT_PASS") << name << ": " << s.dump();

  // The recording: the one capture under data/captures.
  std::vector<fs::path> captures;
  for (const auto& e : fs::directory_iterator(dir_ / "data" / "captures"))
    captures.push_back(e.path());
  ASSERT_EQ(captures.size(), 1u);
  const LinecalRun offline = RunLinecal("calibrate --json --capture " + captures[0].string());
  ASSERT_TRUE(offline.exit_code == 0 || offline.exit_code == 1) << offline.err;
  const std::map<std::string, nlohmann::json> recomputed =
      BySensor(nlohmann::json::parse(offline.out)["sensors"], "name");
  ASSERT_EQ(recomputed.size(), 3u);
  for (const auto& [name, s] : live) {
    SCOPED_TRACE(name);
    const nlohmann::json& r = recomputed.at(name);
    EXPECT_EQ(
        s["verdict"].get<std::string>(), "VERDICT_" + [&] {
          std::string v = r["verdict"];
          for (char& c : v) c = static_cast<char>(std::toupper(c));
          return v;
        }());
    EXPECT_EQ(s.value("reason", std::string()),
              r["reason"].get<std::string>());  // proto JSON omits ""
    EXPECT_EQ(s["features_used"].get<int>(), r["features_used"].get<int>());
    // The pose bit for bit: the same function on the same files.
    const std::vector<double> T_live = s["t_car_sensor"]["m"].get<std::vector<double>>();
    const std::vector<double> T_offline = r["T_car_sensor"].get<std::vector<double>>();
    ASSERT_EQ(T_live.size(), 16u);
    EXPECT_EQ(T_live, T_offline);
  }
  // The camera's frame came over GigE Vision: the recorded PNG is the served one, pixel for
  // pixel (the files' bytes may differ by compression settings; the pixels may not).
  const LinecalRun served =
      RunLinecal("detect --board chessboard --json " +
                 (dir_ / "sensors" / "front_camera" / "frame_0.png").string());
  const LinecalRun recorded = RunLinecal("detect --board chessboard --json " +
                                         (captures[0] / "front_camera" / "frame_0.png").string());
  EXPECT_EQ(served.out, recorded.out);
}

// Packet loss on the fake camera (half the GigE stream packets dropped: no frame arrives
// whole): the camera ends in error with its reason, the LiDAR and radar still get their
// verdicts, and the cycle is stored ended with verdict error and the camera named.
TEST_F(LiveCycleTest, CameraPacketLossEndsThatSensorInErrorOnly) {
  ASSERT_NO_FATAL_FAILURE(Start("0.5"));
  const nlohmann::json cycle = RunCycle();
  ASSERT_FALSE(cycle.is_null());
  EXPECT_EQ(cycle["state"], "CYCLE_STATE_DONE");
  EXPECT_EQ(cycle["verdict"], "VERDICT_ERROR");
  const std::map<std::string, nlohmann::json> live = BySensor(cycle["sensors"], "name");
  ASSERT_EQ(live.size(), 3u);
  EXPECT_EQ(live.at("front_camera")["verdict"], "VERDICT_ERROR");
  const std::string reason = live.at("front_camera")["reason"];
  EXPECT_NE(reason.find("acquisition_failed"), std::string::npos) << reason;
  EXPECT_NE(reason.find("incomplete"), std::string::npos) << reason;
  EXPECT_EQ(live.at("bumper_lidar")["verdict"], "VERDICT_PASS") << live.at("bumper_lidar").dump();
  EXPECT_EQ(live.at("front_radar")["verdict"], "VERDICT_PASS") << live.at("front_radar").dump();
  EXPECT_NE(cycle["reason"].get<std::string>().find("front_camera:acquisition_failed"),
            std::string::npos)
      << cycle["reason"];
}

}  // namespace
}  // namespace linecal
