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

}  // namespace
}  // namespace linecal
