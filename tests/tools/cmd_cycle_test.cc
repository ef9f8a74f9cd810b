// The client against the real daemon binary: linecald started on 127.0.0.1 (a free port)
// with a configuration file (the reference station, a two-sensor car); linecal cycle start
// --wait, cycle show, cycles list and status over gRPC; no daemon and bad requests exit 2;
// the same over mutual TLS with openssl-made certificates, and every TLS refusal.
#include <gtest/gtest.h>
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

#include "tests/daemon/test_car.h"
#include "tests/daemon/test_pki.h"
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
    MakeDir();
    StartDaemon(nlohmann::json::object());
  }
  void MakeDir() {
    dir_ = fs::path(testing::TempDir()) / ("cycle_cli_" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    testing_daemon::WriteTwoSensorCar((dir_ / "car.json").string());
  }
  // The test configuration with `extra`'s keys added.
  nlohmann::json Config(const nlohmann::json& extra) const {
    nlohmann::json config{{"listen", "127.0.0.1:0"},
                          {"station_id", "test-line"},
                          {"station", kDeploy + "/stations/reference.json"},
                          {"car_models", {"car.json"}},
                          {"data_root", "data"},
                          {"auth_token", "t0ken"}};
    config.update(extra);
    return config;
  }
  void StartDaemon(const nlohmann::json& extra) {
    std::ofstream(dir_ / "linecald.json") << Config(extra).dump(2);
    const std::string log = (dir_ / "linecald.log").string();
    daemon_ = ::fork();
    ASSERT_GE(daemon_, 0);
    if (daemon_ == 0) {
      const std::string binary = std::string(LINECAL_BINARY_DIR) + "/bin/linecald";
      const std::string config = (dir_ / "linecald.json").string();
      FILE* err = std::freopen(log.c_str(), "w", stderr);
      (void)err;
      ::execl(binary.c_str(), binary.c_str(), "--config", config.c_str(),
              static_cast<char*>(nullptr));
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
      EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0)
          << "linecald did not stop cleanly on SIGTERM";
    }
    fs::remove_all(dir_);
  }
  fs::path dir_;
  pid_t daemon_ = -1;
  std::string port_;
  std::string connection_;
};

TEST_F(CycleCliTest, CycleStartWaitShowListStatus) {
  const LinecalRun start = RunLinecal(
      "cycle start --vin 1M8GDM9AXKP042788 --car reference --lateral-m 0.01 --wait --json" +
      connection_);
  ASSERT_TRUE(start.exit_code == 0 || start.exit_code == 1) << start.err;
  const nlohmann::json cycle = nlohmann::json::parse(start.out);
  EXPECT_EQ(cycle["vin"], "1M8GDM9AXKP042788");
  EXPECT_EQ(cycle["state"], "CYCLE_STATE_DONE");
  ASSERT_EQ(cycle["sensors"].size(), 2u);
  EXPECT_EQ(start.exit_code == 0, cycle["verdict"] == "VERDICT_PASS");
  EXPECT_NE(start.err.find("SENSOR_VERDICT"), std::string::npos)
      << start.err;  // progress on stderr

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

// The daemon with mutual TLS (and the token): certificates made by openssl in the test's
// directory, next to the configuration, which names them by relative paths.
class TlsCycleCliTest : public CycleCliTest {
 protected:
  void SetUp() override {
    MakeDir();
    ASSERT_TRUE(testing_daemon::MakeTestPki(dir_, &pki_));
    StartDaemon({{"tls",
                  {{"cert", "server.pem"},
                   {"key", "server.key"},
                   {"client_ca", "ca.pem"},
                   {"require_client_cert", true}}}});
    tls_ = " --tls-ca " + pki_.ca_cert + " --tls-cert " + pki_.client_cert + " --tls-key " +
           pki_.client_key;
  }
  testing_daemon::TestPki pki_;
  std::string tls_;
};

TEST_F(TlsCycleCliTest, ClientWithCertificateRunsACycle) {
  const LinecalRun start = RunLinecal(
      "cycle start --vin 1M8GDM9AXKP042788 --car reference --wait --json" + connection_ + tls_);
  ASSERT_TRUE(start.exit_code == 0 || start.exit_code == 1) << start.err;
  const nlohmann::json cycle = nlohmann::json::parse(start.out);
  EXPECT_EQ(cycle["state"], "CYCLE_STATE_DONE");
  EXPECT_EQ(cycle["sensors"].size(), 2u);
  const LinecalRun list = RunLinecal("cycles list --json" + connection_ + tls_);
  ASSERT_EQ(list.exit_code, 0) << list.err;
  EXPECT_EQ(nlohmann::json::parse(list.out)["cycles"].size(), 1u);
  // The certificate names localhost too: the override checks that name on the IP address.
  const LinecalRun named =
      RunLinecal("status --json --tls-server-name localhost" + connection_ + tls_);
  ASSERT_EQ(named.exit_code, 0) << named.err;
  EXPECT_EQ(nlohmann::json::parse(named.out)["station_id"], "test-line");
  // The same files from the environment.
  ::setenv("LINECAL_TLS_CA", pki_.ca_cert.c_str(), 1);
  ::setenv("LINECAL_TLS_CERT", pki_.client_cert.c_str(), 1);
  ::setenv("LINECAL_TLS_KEY", pki_.client_key.c_str(), 1);
  const LinecalRun from_env = RunLinecal("status" + connection_);
  ::unsetenv("LINECAL_TLS_CA");
  ::unsetenv("LINECAL_TLS_CERT");
  ::unsetenv("LINECAL_TLS_KEY");
  EXPECT_EQ(from_env.exit_code, 0) << from_env.err;
  EXPECT_NE(from_env.out.find("station test-line"), std::string::npos) << from_env.out;
}

TEST_F(TlsCycleCliTest, RefusalsNameTheFlagOrTheHandshake) {
  const std::string missing = (dir_ / "missing.pem").string();
  const LinecalRun no_file = RunLinecal("status --tls-ca " + missing + connection_);
  EXPECT_EQ(no_file.exit_code, 2);
  EXPECT_EQ(no_file.err.rfind("linecal status: --tls-ca: " + missing + ": cannot read", 0), 0u)
      << no_file.err;
  const LinecalRun no_key = RunLinecal("cycles list --tls-key " + missing + connection_);
  EXPECT_EQ(no_key.exit_code, 2);
  EXPECT_NE(no_key.err.find("--tls-key: " + missing), std::string::npos) << no_key.err;
  const LinecalRun half = RunLinecal("status --tls-ca " + pki_.ca_cert + " --tls-cert " +
                                     pki_.client_cert + connection_);
  EXPECT_EQ(half.exit_code, 2);
  EXPECT_NE(half.err.find("--tls-cert and --tls-key"), std::string::npos) << half.err;
  // No client certificate, one from another CA, a name the certificate does not carry: the
  // handshake fails, which gRPC reports as UNAVAILABLE.
  for (const std::string& flags :
       {" --tls-ca " + pki_.ca_cert,
        " --tls-ca " + pki_.ca_cert + " --tls-cert " + pki_.other_client_cert + " --tls-key " +
            pki_.other_client_key,
        tls_ + " --tls-server-name linecald.example"}) {
    const LinecalRun refused = RunLinecal("status" + connection_ + flags);
    EXPECT_EQ(refused.exit_code, 2) << flags;
    EXPECT_NE(refused.err.find("no daemon answers or the TLS handshake failed"), std::string::npos)
        << refused.err;
  }
  const LinecalRun insecure = RunLinecal("status" + connection_);
  EXPECT_EQ(insecure.exit_code, 2);
  EXPECT_NE(insecure.err.find("no daemon answers"), std::string::npos) << insecure.err;
  const LinecalRun no_token = RunLinecal("status --address 127.0.0.1:" + port_ + tls_);
  EXPECT_EQ(no_token.exit_code, 2);
  EXPECT_NE(no_token.err.find("bearer token"), std::string::npos) << no_token.err;
}

// A key that does not belong to the certificate stops linecald at start-up with a message
// naming both files.
TEST(LinecaldTls, MismatchedKeyStopsTheStart) {
  const fs::path dir =
      fs::path(testing::TempDir()) / ("linecald_tls_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  testing_daemon::TestPki pki;
  ASSERT_TRUE(testing_daemon::MakeTestPki(dir, &pki));
  testing_daemon::WriteTwoSensorCar((dir / "car.json").string());
  std::ofstream(dir / "linecald.json") << nlohmann::json{
      {"listen", "127.0.0.1:0"},
      {"station", kDeploy + "/stations/reference.json"},
      {"car_models", {"car.json"}},
      {"data_root", "data"},
      {"tls", {{"cert", "server.pem"}, {"key", "client.key"}, {"client_ca", "ca.pem"}}}};
  const std::string command = std::string(LINECAL_BINARY_DIR) + "/bin/linecald --config '" +
                              (dir / "linecald.json").string() + "' 2>&1";
  FILE* pipe = popen(command.c_str(), "r");
  ASSERT_NE(pipe, nullptr);
  std::string out;
  char buffer[4096];
  for (std::size_t n; (n = std::fread(buffer, 1, sizeof buffer, pipe)) > 0;) out.append(buffer, n);
  const int status = pclose(pipe);
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 1);
  EXPECT_NE(out.find("linecald: tls.key: " + pki.client_key +
                     ": does not match the certificate of tls.cert (" + pki.server_cert + ")"),
            std::string::npos)
      << out;
  fs::remove_all(dir);
}

}  // namespace
}  // namespace linecal
