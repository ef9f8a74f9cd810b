// The client against the real daemon binary: linecald started on 127.0.0.1 (a free port)
// with a configuration file (the reference station, a two-sensor car); linecal cycle start
// --wait, cycle show, cycles list and status over gRPC; no daemon and bad requests exit 2.
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <regex>
#include <sstream>
#include <string>
#include <thread>

#include <gtest/gtest.h>

#include "tests/daemon/test_car.h"

#include "tests/tools/run_linecal.h"

namespace linecal {
namespace {

namespace fs = std::filesystem;
using testing_tools::LinecalRun;
using testing_tools::RunLinecal;
const std::string kDeploy = std::string(LINECAL_SOURCE_DIR) + "/deploy";

class CycleCliTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::path(testing::TempDir()) / ("cycle_cli_" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    testing_daemon::WriteTwoSensorCar((dir_ / "car.json").string());
    std::ofstream(dir_ / "linecald.json") << nlohmann::json{{"listen", "127.0.0.1:0"},
                                                            {"station_id", "test-line"},
                                                            {"station", kDeploy + "/stations/reference.json"},
                                                            {"car_models", {"car.json"}},
                                                            {"data_root", "data"},
                                                            {"auth_token", "t0ken"}}
                                                 .dump(2);
    const std::string log = (dir_ / "linecald.log").string();
    daemon_ = ::fork();
    ASSERT_GE(daemon_, 0);
    if (daemon_ == 0) {
      const std::string binary = std::string(LINECAL_BINARY_DIR) + "/bin/linecald";
      const std::string config = (dir_ / "linecald.json").string();
      FILE* err = std::freopen(log.c_str(), "w", stderr);
      (void)err;
      ::execl(binary.c_str(), binary.c_str(), "--config", config.c_str(), static_cast<char*>(nullptr));
      ::_exit(127);
    }
    // The first log line names the port the kernel picked.
    const std::regex port_re("\\(port ([0-9]+)\\)");
    for (int i = 0; i < 200 && port_.empty(); ++i) {
      std::ifstream f(log);
      std::stringstream text;
      text << f.rdbuf();
      std::smatch m;
      const std::string s = text.str();
      if (std::regex_search(s, m, port_re)) port_ = m[1];
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    ASSERT_FALSE(port_.empty()) << "linecald did not start";
    connection_ = " --address 127.0.0.1:" + port_ + " --token t0ken";
  }
  void TearDown() override {
    if (daemon_ > 0) {
      ::kill(daemon_, SIGTERM);
      int status = 0;
      ::waitpid(daemon_, &status, 0);
      EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << "linecald did not stop cleanly on SIGTERM";
    }
    fs::remove_all(dir_);
  }
  fs::path dir_;
  pid_t daemon_ = -1;
  std::string port_;
  std::string connection_;
};

TEST_F(CycleCliTest, CycleStartWaitShowListStatus) {
  const LinecalRun start = RunLinecal("cycle start --vin 1M8GDM9AXKP042788 --car reference --lateral-m 0.01 --wait --json" +
                                      connection_);
  ASSERT_TRUE(start.exit_code == 0 || start.exit_code == 1) << start.err;
  const nlohmann::json cycle = nlohmann::json::parse(start.out);
  EXPECT_EQ(cycle["vin"], "1M8GDM9AXKP042788");
  EXPECT_EQ(cycle["state"], "CYCLE_STATE_DONE");
  ASSERT_EQ(cycle["sensors"].size(), 2u);
  EXPECT_EQ(start.exit_code == 0, cycle["verdict"] == "VERDICT_PASS");
  EXPECT_NE(start.err.find("SENSOR_VERDICT"), std::string::npos) << start.err;  // progress on stderr

  const std::string id = cycle["cycle_id"];
  const LinecalRun show = RunLinecal("cycle show " + id + connection_);
  EXPECT_EQ(show.exit_code, 0) << show.err;
  EXPECT_NE(show.out.find("front_camera"), std::string::npos) << show.out;
  const LinecalRun list = RunLinecal("cycles list --json --vin 1M8GDM9AXKP042788" + connection_);
  ASSERT_EQ(list.exit_code, 0) << list.err;
  EXPECT_EQ(nlohmann::json::parse(list.out)["cycles"].size(), 1u);
  const LinecalRun status = RunLinecal("status --json" + connection_);
  ASSERT_EQ(status.exit_code, 0) << status.err;
  EXPECT_EQ(nlohmann::json::parse(status.out)["station_id"], "test-line");
}

TEST_F(CycleCliTest, RefusalsAndNoDaemon) {
  const LinecalRun bad_vin = RunLinecal("cycle start --vin 123 --car reference" + connection_);
  EXPECT_EQ(bad_vin.exit_code, 2);
  EXPECT_NE(bad_vin.err.find("vin"), std::string::npos) << bad_vin.err;
  const LinecalRun no_token = RunLinecal("status --address 127.0.0.1:" + port_);
  EXPECT_EQ(no_token.exit_code, 2);
  EXPECT_NE(no_token.err.find("bearer token"), std::string::npos) << no_token.err;
  const LinecalRun unknown = RunLinecal("cycle show 4242" + connection_);
  EXPECT_EQ(unknown.exit_code, 1);
  // A port nobody listens on: the daemon's own port after it stopped.
  ::kill(daemon_, SIGTERM);
  ::waitpid(daemon_, nullptr, 0);
  daemon_ = -1;
  const LinecalRun gone = RunLinecal("status" + connection_);
  EXPECT_EQ(gone.exit_code, 2);
  EXPECT_NE(gone.err.find("no daemon answers"), std::string::npos) << gone.err;
}

}  // namespace
}  // namespace linecal
