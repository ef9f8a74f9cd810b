// linecald's configuration file: a full file reads back with relative paths resolved against
// it; every bad key or value is refused naming the file and the key.
#include "daemon/core/daemon_config.h"

#include <filesystem>
#include <fstream>
#include <string>

#include <gtest/gtest.h>
#include <unistd.h>

namespace linecal {
namespace {

namespace fs = std::filesystem;

class DaemonConfigTest : public ::testing::Test {
 protected:
  void SetUp() override {
    // Per test and process: ctest runs the tests in parallel, each in its own process.
    dir_ = fs::path(testing::TempDir()) / ("daemon_config_" + std::to_string(::getpid()) + "_" +
                                           testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(dir_);
  }
  absl::StatusOr<DaemonConfig> Read(const std::string& text) {
    const fs::path path = dir_ / "linecald.json";
    std::ofstream(path) << text;
    return ReadDaemonConfig(path.string());
  }
  fs::path dir_;
};

TEST_F(DaemonConfigTest, FullFileReadsBack) {
  absl::StatusOr<DaemonConfig> c = Read(R"({
    "listen": "0.0.0.0:7000", "log_level": "debug", "auth_token": "t", "station_id": "line-3",
    "station": "stations/a.json", "car_models": ["cars/x.json", "/abs/y.json"],
    "data_root": "data", "db": "station.db", "source": {"type": "replay", "capture": "rec/1"},
    "vin_check_digit": false, "frames_per_sensor": 3, "busy_timeout_ms": 250})");
  ASSERT_TRUE(c.ok()) << c.status();
  EXPECT_EQ(c->listen, "0.0.0.0:7000");
  EXPECT_EQ(c->log_level, "debug");
  EXPECT_EQ(c->auth_token, "t");
  EXPECT_EQ(c->core.station_id, "line-3");
  EXPECT_EQ(c->core.station_path, (dir_ / "stations/a.json").string());
  EXPECT_EQ(c->core.car_model_paths, (std::vector<std::string>{(dir_ / "cars/x.json").string(), "/abs/y.json"}));
  EXPECT_EQ(c->core.db_path, (dir_ / "data" / "station.db").string());
  EXPECT_EQ(c->core.source, CycleSource::kReplay);
  EXPECT_EQ(c->core.replay_capture, "rec/1");
  EXPECT_FALSE(c->core.vin_check_digit);
  EXPECT_EQ(c->core.default_frames_per_sensor, 3);
  EXPECT_EQ(c->core.busy_timeout.count(), 250);
}

TEST_F(DaemonConfigTest, ErrorsNameTheKey) {
  const std::string base = R"("station": "s.json", "car_models": ["c.json"], "data_root": "d")";
  const std::pair<std::string, std::string> cases[] = {
      {"{" + base + R"(, "colour": 1})", "colour"},
      {"{" + base + R"(, "log_level": "loud"})", "log_level"},
      {"{" + base + R"(, "source": {"type": "usb"}})", "source.type"},
      {"{" + base + R"(, "source": {"type": "replay"}})", "source.capture"},
      {"{" + base + R"(, "frames_per_sensor": 0})", "frames_per_sensor"},
      {R"({"car_models": ["c.json"], "data_root": "d"})", "station"},
      {"{" + base + R"(, "listen": 7})", "listen"},
  };
  for (const auto& [text, key] : cases) {
    const absl::Status s = Read(text).status();
    EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument) << text;
    EXPECT_NE(s.message().find("linecald.json"), std::string::npos) << s.message();
    EXPECT_NE(s.message().find(key), std::string::npos) << key << ": " << s.message();
  }
}

// The tls object: paths relative to the file, the files read (their PEM is checked by the
// service, tests/daemon/service), and every missing piece refused naming key and file.
TEST_F(DaemonConfigTest, TlsFilesReadNamingKeyAndFile) {
  fs::create_directories(dir_ / "pki");
  std::ofstream(dir_ / "pki/server.pem") << "CERT";
  std::ofstream(dir_ / "pki/server.key") << "KEY";
  std::ofstream(dir_ / "pki/ca.pem") << "CA";
  const std::string base = R"("station": "s.json", "car_models": ["c.json"], "data_root": "d")";
  absl::StatusOr<DaemonConfig> c = Read("{" + base + R"(, "tls": {"cert": "pki/server.pem", "key": "pki/server.key",
      "client_ca": "pki/ca.pem", "require_client_cert": true}})");
  ASSERT_TRUE(c.ok()) << c.status();
  ASSERT_TRUE(c->tls.has_value());
  EXPECT_EQ(c->tls->cert_path, (dir_ / "pki/server.pem").string());
  EXPECT_EQ(c->tls->key_path, (dir_ / "pki/server.key").string());
  EXPECT_EQ(c->tls->client_ca_path, (dir_ / "pki/ca.pem").string());
  EXPECT_EQ(c->tls->cert_pem, "CERT");
  EXPECT_EQ(c->tls->key_pem, "KEY");
  EXPECT_EQ(c->tls->client_ca_pem, "CA");
  EXPECT_TRUE(c->tls->require_client_cert);
  // Server-only TLS (the token authenticates): no client_ca, require_client_cert false.
  c = Read("{" + base + R"(, "tls": {"cert": "pki/server.pem", "key": "pki/server.key", "require_client_cert": false}})");
  ASSERT_TRUE(c.ok()) << c.status();
  EXPECT_TRUE(c->tls->client_ca_path.empty());
  EXPECT_FALSE(c->tls->require_client_cert);
  EXPECT_FALSE(Read("{" + base + "}")->tls.has_value());

  const std::string missing = (dir_ / "pki/missing.pem").string();
  const std::pair<std::string, std::string> cases[] = {
      {R"({"cert": "pki/missing.pem", "key": "pki/server.key", "client_ca": "pki/ca.pem"})",
       "linecald.json: tls.cert: " + missing + ": cannot read"},
      {R"({"cert": "pki/server.pem", "key": "pki/missing.pem", "client_ca": "pki/ca.pem"})",
       "linecald.json: tls.key: " + missing + ": cannot read"},
      {R"({"cert": "pki/server.pem", "key": "pki/server.key", "client_ca": "pki/missing.pem"})",
       "linecald.json: tls.client_ca: " + missing + ": cannot read"},
      {R"({"cert": "pki/server.pem", "key": "pki/server.key"})", "linecald.json: tls.client_ca: required"},
      {R"({"key": "pki/server.key", "client_ca": "pki/ca.pem"})", "linecald.json: tls.cert"},
      {R"({"cert": "pki/server.pem", "key": "pki/server.key", "client_ca": "pki/ca.pem", "ca": "x"})",
       "linecald.json: tls.ca"},
      {R"("on")", "linecald.json: tls"},
  };
  for (const auto& [tls, expected] : cases) {
    const absl::Status s = Read("{" + base + R"(, "tls": )" + tls + "}").status();
    EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument) << tls;
    EXPECT_NE(s.message().find(expected), std::string::npos) << expected << " | " << s.message();
  }
}

}  // namespace
}  // namespace linecal
