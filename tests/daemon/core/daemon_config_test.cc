// linecald's configuration file: a full file reads back with relative paths resolved against
// it; every bad key or value is refused naming the file and the key.
#include "daemon/core/daemon_config.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>

namespace linecal {
namespace {

namespace fs = std::filesystem;

class DaemonConfigTest : public ::testing::Test {
 protected:
  void SetUp() override {
    // Per test and process: ctest runs the tests in parallel, each in its own process.
    dir_ = fs::path(testing::TempDir()) /
           ("daemon_config_" + std::to_string(::getpid()) + "_" +
            testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
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
  EXPECT_EQ(c->core.car_model_paths,
            (std::vector<std::string>{(dir_ / "cars/x.json").string(), "/abs/y.json"}));
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

// The input budget (issue 21, item 4): defaults when absent, every key read, bad values and
// unknown keys refused naming the key.
TEST_F(DaemonConfigTest, InputBudgetReadsBackAndDefaults) {
  const std::string base = R"("station": "s.json", "car_models": ["c.json"], "data_root": "d")";
  absl::StatusOr<DaemonConfig> defaults = Read("{" + base + "}");
  ASSERT_TRUE(defaults.ok()) << defaults.status();
  EXPECT_EQ(defaults->input_budget.max_image_pixels, 50'000'000);
  EXPECT_EQ(defaults->input_budget.max_manifest_frames, 1000);
  absl::StatusOr<DaemonConfig> c = Read("{" + base + R"(, "input_budget": {"max_file_bytes": 1000,
      "max_image_pixels": 2000, "max_scan_points": 3000, "max_can_lines": 4000,
      "max_manifest_frames": 5}})");
  ASSERT_TRUE(c.ok()) << c.status();
  EXPECT_EQ(c->input_budget.max_file_bytes, 1000);
  EXPECT_EQ(c->input_budget.max_image_pixels, 2000);
  EXPECT_EQ(c->input_budget.max_scan_points, 3000);
  EXPECT_EQ(c->input_budget.max_can_lines, 4000);
  EXPECT_EQ(c->input_budget.max_manifest_frames, 5);
  absl::Status zero = Read("{" + base + R"(, "input_budget": {"max_can_lines": 0}})").status();
  EXPECT_NE(zero.message().find("input_budget.max_can_lines: must be >= 1, got 0"),
            std::string::npos)
      << zero;
  absl::Status unknown = Read("{" + base + R"(, "input_budget": {"max_pixels": 9}})").status();
  EXPECT_NE(unknown.message().find("max_pixels"), std::string::npos) << unknown;
}

// A replay capture folder that is a symbolic link out of data_root is refused (issue 21,
// item 5); one that is a link to another folder inside data_root is followed.
TEST_F(DaemonConfigTest, ReplayCaptureLinkedOutsideDataRootIsRefused) {
  fs::create_directories(dir_ / "data/captures/real");
  fs::create_directories(dir_ / "elsewhere/cap");
  fs::create_directory_symlink(dir_ / "elsewhere/cap", dir_ / "data/captures/evil");
  fs::create_directory_symlink(dir_ / "data/captures/real", dir_ / "data/captures/alias");
  // A sibling whose name starts with data_root's: outside, though a string prefix says inside.
  fs::create_directories(dir_ / "data2/cap");
  fs::create_directory_symlink(dir_ / "data2/cap", dir_ / "data/captures/prefix");
  const std::string base = R"("station": "s.json", "car_models": ["c.json"], "data_root": "data")";
  for (const char* link : {"captures/evil", "captures/prefix"}) {
    const absl::Status s =
        Read("{" + base + R"(, "source": {"type": "replay", "capture": ")" + link + R"("}})")
            .status();
    EXPECT_NE(
        s.message().find(std::string("source.capture: '") + link + "': resolves outside data_root"),
        std::string::npos)
        << s;
  }
  absl::StatusOr<DaemonConfig> inside =
      Read("{" + base + R"(, "source": {"type": "replay", "capture": "captures/alias"}})");
  ASSERT_TRUE(inside.ok()) << inside.status();
  EXPECT_EQ(inside->core.replay_capture, "captures/alias");
}

// The tls object: paths relative to the file, the files read (their PEM is checked by the
// service, tests/daemon/service), and every missing piece refused naming key and file.
TEST_F(DaemonConfigTest, TlsFilesReadNamingKeyAndFile) {
  fs::create_directories(dir_ / "pki");
  std::ofstream(dir_ / "pki/server.pem") << "CERT";
  std::ofstream(dir_ / "pki/server.key") << "KEY";
  std::ofstream(dir_ / "pki/ca.pem") << "CA";
  const std::string base = R"("station": "s.json", "car_models": ["c.json"], "data_root": "d")";
  absl::StatusOr<DaemonConfig> c =
      Read("{" + base + R"(, "tls": {"cert": "pki/server.pem", "key": "pki/server.key",
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
  c = Read(
      "{" + base +
      R"(, "tls": {"cert": "pki/server.pem", "key": "pki/server.key", "require_client_cert": false}})");
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
      {R"({"cert": "pki/server.pem", "key": "pki/server.key"})",
       "linecald.json: tls.client_ca: required"},
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

TEST_F(DaemonConfigTest, LiveSourcesAndDeadlinesReadBack) {
  absl::StatusOr<DaemonConfig> c = Read(R"({
    "station": "s.json", "car_models": ["c.json"], "data_root": "d",
    "deadlines_ms": {"acquire": 4000, "calibrate": 9000},
    "source": {"type": "live", "sensors": {
      "front_camera": {"type": "aravis", "device_id": "Aravis-Fake-TEST01", "pixel_format": "BayerRG8",
                       "exposure_us": 5000, "frame_timeout_ms": 1500, "frame_retries": 2},
      "rear_camera": {"type": "v4l2", "device": "/dev/video2", "width": 1280, "height": 720},
      "roof_lidar": {"type": "udp", "bind": "127.0.0.1", "port": 2369, "multicast_group": "239.1.1.1",
                     "receive_buffer_bytes": 1048576},
      "front_radar": {"type": "candump", "log": "logs/radar.log", "interface": "can1", "record_ms": 2000},
      "corner_radar": {"type": "socketcan", "interface": "can0"}}}})");
  ASSERT_TRUE(c.ok()) << c.status();
  EXPECT_EQ(c->core.source, CycleSource::kLive);
  EXPECT_EQ(c->core.acquire_deadline.count(), 4000);
  EXPECT_EQ(c->core.calibrate_deadline.count(), 9000);
  ASSERT_EQ(c->core.live_sources.size(), 5u);
  const SourceConfig& cam = c->core.live_sources.at("front_camera");
  EXPECT_EQ(cam.type, SourceType::kAravis);
  EXPECT_EQ(cam.aravis.device_id, "Aravis-Fake-TEST01");
  EXPECT_EQ(cam.aravis.pixel_format, "BayerRG8");
  EXPECT_EQ(cam.aravis.exposure_us, 5000);
  EXPECT_EQ(cam.aravis.frame_timeout.count(), 1500);
  EXPECT_EQ(cam.aravis.frame_retries, 2);
  const SourceConfig& v4l2 = c->core.live_sources.at("rear_camera");
  EXPECT_EQ(v4l2.type, SourceType::kV4l2);
  EXPECT_EQ(v4l2.v4l2.device, "/dev/video2");
  EXPECT_EQ(v4l2.v4l2.pixel_format, "GREY");
  EXPECT_EQ(v4l2.v4l2.width, 1280);
  EXPECT_EQ(v4l2.v4l2.height, 720);
  EXPECT_EQ(v4l2.v4l2.frame_retries, 3);
  const SourceConfig& lidar = c->core.live_sources.at("roof_lidar");
  EXPECT_EQ(lidar.type, SourceType::kUdp);
  EXPECT_EQ(lidar.udp.bind_address, "127.0.0.1");
  EXPECT_EQ(lidar.udp.port, 2369);
  EXPECT_EQ(lidar.udp.multicast_group, "239.1.1.1");
  EXPECT_EQ(lidar.udp.receive_buffer_bytes, 1048576);
  const SourceConfig& log = c->core.live_sources.at("front_radar");
  EXPECT_EQ(log.type, SourceType::kCandump);
  EXPECT_EQ(log.can.input, CanRadarSourceConfig::Input::kCandumpLog);
  EXPECT_EQ(log.can.log_path, (dir_ / "logs/radar.log").string());
  EXPECT_EQ(log.can.interface, "can1");
  EXPECT_EQ(log.can.record.count(), 2000);
  const SourceConfig& bus = c->core.live_sources.at("corner_radar");
  EXPECT_EQ(bus.type, SourceType::kSocketCan);
  EXPECT_EQ(bus.can.interface, "can0");
  EXPECT_EQ(bus.can.record.count(), 3600);
}

TEST_F(DaemonConfigTest, DeadlinesDefaultAndLiveErrorsNameTheKey) {
  const std::string base = R"("station": "s.json", "car_models": ["c.json"], "data_root": "d")";
  absl::StatusOr<DaemonConfig> plain = Read("{" + base + "}");
  ASSERT_TRUE(plain.ok());
  EXPECT_EQ(plain->core.acquire_deadline.count(), 10000);
  EXPECT_EQ(plain->core.calibrate_deadline.count(), 20000);
  const auto live = [&](const std::string& sensors) {
    return "{" + base + R"(, "source": {"type": "live", "sensors": )" + sensors + "}}";
  };
  const std::pair<std::string, std::string> cases[] = {
      {live(R"({"front_camera": {"type": "usb"}})"),
       "source.sensors.front_camera.type: must be aravis, v4l2, udp, socketcan or candump, got "
       "'usb'"},
      {live(R"({"front_camera": {"type": "aravis"}})"), "source.sensors.front_camera.device_id"},
      {live(R"({"front_camera": {"type": "aravis", "device_id": "x", "colour": 1}})"),
       "source.sensors.front_camera.colour"},
      {live(R"({"front_camera": {"type": "aravis", "device_id": "x", "frame_retries": -1}})"),
       "source.sensors.front_camera.frame_retries: must be in [0, 100]"},
      {live(R"({"roof_lidar": {"type": "udp", "port": 70000}})"),
       "source.sensors.roof_lidar.port: must be in [1, 65535], got 70000"},
      {live(R"({"roof_lidar": {"type": "udp", "bind": "localhost"}})"),
       "source.sensors.roof_lidar: "},
      {live(R"({"roof_lidar": {"type": "udp", "log": "x"}})"), "source.sensors.roof_lidar.log"},
      {live(R"({"front_radar": {"type": "socketcan"}})"), "source.sensors.front_radar.interface"},
      {live(R"({"front_radar": {"type": "candump", "log": "r.log", "record_ms": 0}})"),
       "source.sensors.front_radar.record_ms: must be in [1, 600000], got 0"},
      {live(R"({"front_radar": {"type": "candump", "log": "r.log", "record_ms": 70000}})"),
       "source.sensors.front_radar: record_ms: 70000 must be in [1, 60000]"},
      {live(R"({"front_radar": 3})"), "source.sensors.front_radar"},
      {"{" + base + R"(, "source": {"type": "live"}})", "source.sensors"},
      {"{" + base + R"(, "source": {"type": "live", "sensors": {}, "capture": "x"}})",
       "source.capture"},
      {"{" + base + R"(, "deadlines_ms": {"acquire": 0}})",
       "deadlines_ms.acquire: must be in [1, 600000], got 0"},
      {"{" + base + R"(, "deadlines_ms": {"solve": 5}})", "deadlines_ms.solve"},
  };
  for (const auto& [text, key] : cases) {
    const absl::Status s = Read(text).status();
    EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument) << text;
    EXPECT_NE(s.message().find("linecald.json: "), std::string::npos) << s.message();
    EXPECT_NE(s.message().find(key), std::string::npos) << key << ": " << s.message();
  }
}

// The `plant` section (docs/daemon.md, "Plant database"): defaults, the password file's first
// line, tls files resolved against the file, and errors that name the key and never quote a
// password.
TEST_F(DaemonConfigTest, PlantSectionReadsBackAndDefaults) {
  const std::string base = R"("station": "s.json", "car_models": ["c.json"], "data_root": "d",
    "station_id": "line-3")";
  absl::StatusOr<DaemonConfig> none = Read("{" + base + "}");
  ASSERT_TRUE(none.ok()) << none.status();
  EXPECT_FALSE(none->core.plant.has_value());

  std::ofstream(dir_ / "plant.pass") << "s3cret'pw\nsecond line\n";
  std::ofstream(dir_ / "ca.pem") << "-----BEGIN CERTIFICATE-----\n";
  absl::StatusOr<DaemonConfig> c = Read("{" + base + R"(, "plant": {
    "dsn": "host=plant port=5433 dbname=linecal user=station", "batch": 250,
    "password_file": "plant.pass", "max_backlog_age_s": 600, "max_retry_interval_s": 5,
    "tls": {"mode": "verify-ca", "ca": "ca.pem"}}})");
  ASSERT_TRUE(c.ok()) << c.status();
  ASSERT_TRUE(c->core.plant.has_value());
  const PlantConfig& p = *c->core.plant;
  EXPECT_EQ(p.dsn, "host=plant port=5433 dbname=linecal user=station");
  EXPECT_EQ(p.station_id, "line-3");  // the top-level station_id
  EXPECT_EQ(p.batch, 250);
  EXPECT_EQ(p.password, "s3cret'pw");
  EXPECT_EQ(p.max_backlog_age, std::chrono::seconds(600));
  EXPECT_EQ(p.max_retry_interval, std::chrono::seconds(5));
  ASSERT_TRUE(p.tls.has_value());
  EXPECT_EQ(p.tls->mode, "verify-ca");
  EXPECT_EQ(p.tls->ca_path, (dir_ / "ca.pem").string());
  EXPECT_TRUE(p.tls->cert_path.empty());

  absl::StatusOr<DaemonConfig> d = Read("{" + base + R"(, "plant": {"dsn": "host=plant",
    "station_id": "eol-7"}})");
  ASSERT_TRUE(d.ok()) << d.status();
  EXPECT_EQ(d->core.plant->station_id, "eol-7");
  EXPECT_EQ(d->core.plant->batch, 100);
  EXPECT_EQ(d->core.plant->max_backlog_age, std::chrono::seconds(3600));
  EXPECT_FALSE(d->core.plant->tls.has_value());
  EXPECT_TRUE(d->core.plant->password.empty());
}

TEST_F(DaemonConfigTest, PlantErrorsNameTheKeyAndNeverThePassword) {
  const std::string base = R"("station": "s.json", "car_models": ["c.json"], "data_root": "d")";
  std::ofstream(dir_ / "empty.pass") << "\n";
  const std::pair<std::string, std::string> cases[] = {
      {R"({"batch": 5})", "plant.dsn"},
      {R"({"dsn": "host=h password=hunter2"})", "plant.dsn"},
      {R"({"dsn": "postgresql://u:hunter2@h/db"})", "plant.dsn"},
      {R"({"dsn": "host=h bogus"})", "plant.dsn"},
      {R"({"dsn": "host=h", "batch": 0})", "plant.batch"},
      {R"({"dsn": "host=h", "batch": 10001})", "plant.batch"},
      {R"({"dsn": "host=h", "max_backlog_age_s": 0})", "plant.max_backlog_age_s"},
      {R"({"dsn": "host=h", "max_retry_interval_s": 3601})", "plant.max_retry_interval_s"},
      {R"({"dsn": "host=h", "station_id": ""})", "plant.station_id"},
      {R"({"dsn": "host=h", "password_file": "missing.pass"})", "plant.password_file"},
      {R"({"dsn": "host=h", "password_file": "empty.pass"})", "plant.password_file"},
      {R"({"dsn": "host=h", "tls": {"mode": "prefer"}})", "plant.tls.mode"},
      {R"({"dsn": "host=h", "tls": {"ca": "nope.pem"}})", "plant.tls.ca"},
      {R"({"dsn": "host=h", "tls": {"cert": "nope.pem"}})", "plant.tls.cert"},
      {R"({"dsn": "host=h", "colour": 1})", "colour"},
  };
  for (const auto& [plant, key] : cases) {
    const absl::StatusOr<DaemonConfig> c = Read("{" + base + R"(, "plant": )" + plant + "}");
    ASSERT_FALSE(c.ok()) << plant;
    EXPECT_EQ(c.status().code(), absl::StatusCode::kInvalidArgument) << plant;
    const std::string message(c.status().message());
    EXPECT_NE(message.find(key), std::string::npos) << plant << " -> " << message;
    EXPECT_EQ(message.find("hunter2"), std::string::npos) << message;
  }
}

}  // namespace
}  // namespace linecal

namespace linecal {
namespace {

// The `web` key (the station console): read back with the folder resolved, and each bad value
// refused naming web.<key>.
TEST_F(DaemonConfigTest, WebKeyReadsBackAndIsChecked) {
  const std::string head = R"({"station": "s.json", "car_models": [], "data_root": "data", )";
  fs::create_directories(dir_ / "pages");
  absl::StatusOr<DaemonConfig> c =
      Read(head + R"("web": {"listen": "127.0.0.1:8080", "static_dir": "pages"}})");
  ASSERT_TRUE(c.ok()) << c.status();
  ASSERT_TRUE(c->web.has_value());
  EXPECT_EQ(c->web->listen, "127.0.0.1:8080");
  EXPECT_EQ(c->web->static_dir, (dir_ / "pages").string());
  EXPECT_FALSE(c->web->tls.has_value());
  EXPECT_EQ(c->web->operator_token, "");
  absl::StatusOr<DaemonConfig> operators =
      Read(head + R"("auth_token": "a", "web": {"listen": "h:1", "operator_token": "b"}})");
  ASSERT_TRUE(operators.ok()) << operators.status();
  EXPECT_EQ(operators->web->operator_token, "b");
  absl::StatusOr<DaemonConfig> none = Read(head + R"("listen": "127.0.0.1:1"})");
  ASSERT_TRUE(none.ok()) << none.status();
  EXPECT_FALSE(none->web.has_value());

  const std::pair<std::string, std::string> bad[] = {
      {R"("web": {})", "web.listen: missing"},
      {R"("web": {"listen": "8080"})",
       "web.listen: '8080': must be HOST:PORT with a port in 0..65535"},
      {R"("web": {"listen": "h:70000"})", "web.listen: 'h:70000': must be HOST:PORT"},
      {R"("web": {"listen": "h:1", "port": 2})", "web.port"},
      {R"("web": {"listen": "h:1", "static_dir": "nowhere"})", "web.static_dir: '"},
      {R"("web": {"listen": "h:1", "tls": {"cert": "c.pem"}})", "web.tls.cert"},
      {R"("web": "127.0.0.1:8080")", "web: expected an object"},
      {R"("web": {"listen": "h:1", "operator_token": 7})", "web.operator_token"},
      {R"("auth_token": "same", "web": {"listen": "h:1", "operator_token": "same"})",
       "web.operator_token: must differ from auth_token"},
  };
  for (const auto& [text, expected] : bad) {
    absl::StatusOr<DaemonConfig> r = Read(head + text + "}");
    ASSERT_FALSE(r.ok()) << text;
    EXPECT_EQ(r.status().code(), absl::StatusCode::kInvalidArgument) << text;
    EXPECT_NE(std::string(r.status().message()).find(expected), std::string::npos)
        << text << " -> " << r.status().message();
  }
}

}  // namespace
}  // namespace linecal

namespace linecal {
namespace {

// source.moved_boards (the simulator's moved boards): read back, and each bad value refused
// naming the entry's key.
TEST_F(DaemonConfigTest, MovedBoardsReadBackAndAreChecked) {
  const std::string head = R"({"station": "s.json", "car_models": [], "data_root": "data", )";
  absl::StatusOr<DaemonConfig> c = Read(head + R"("source": {"type": "simulator", "moved_boards": [
      {"board": "bumper_lidar_left", "ypr_deg": [0.3, 0, -0.1], "xyz_m": [0.01, 0, 0], "from_cycle": 16},
      {"board": "front_circle", "ypr_deg": [0, 1, 0]}]}})");
  ASSERT_TRUE(c.ok()) << c.status();
  ASSERT_EQ(c->core.simulated_moves.size(), 2u);
  const SimulatedBoardMove& m = c->core.simulated_moves[0];
  EXPECT_EQ(m.move.board_id, "bumper_lidar_left");
  EXPECT_EQ(m.move.yaw_deg, 0.3);
  EXPECT_EQ(m.move.roll_deg, -0.1);
  EXPECT_EQ(m.move.offset_m.x(), 0.01);
  EXPECT_EQ(m.from_cycle, 16);
  EXPECT_EQ(c->core.simulated_moves[1].from_cycle, 1);
  EXPECT_EQ(c->core.simulated_moves[1].move.pitch_deg, 1.0);

  const std::pair<std::string, std::string> bad[] = {
      {R"([{"ypr_deg": [0, 0, 0]}])", "source.moved_boards[0].board: missing"},
      {R"([{"board": "b", "ypr_deg": [0, 0]}])", "source.moved_boards[0].ypr_deg"},
      {R"([{"board": "b", "ypr_deg": [0, 0, 0], "from_cycle": 0}])",
       "source.moved_boards[0].from_cycle: must be >= 1"},
      {R"([{"board": "b", "ypr_deg": [20, 0, 0]}])",
       "moved_boards[0].ypr_deg = 20: must be in [0, 10]"},
      {R"([{"board": "b", "ypr_deg": [0, 0, 0], "xyz_m": [1, 0, 0]}])",
       "moved_boards[0].xyz_m: each must be in [-0.5, 0.5]"},
      {R"([{"board": "b", "ypr_deg": [0, 0, 0]}, {"board": "b", "ypr_deg": [1, 0, 0]}])",
       "moved_boards[1].board_id: 'b' moved twice"},
      {R"([{"board": "b", "ypr_deg": [0, 0, 0], "turn": 1}])", "source.moved_boards[0].turn"},
  };
  for (const auto& [moves, expected] : bad) {
    absl::StatusOr<DaemonConfig> r =
        Read(head + R"("source": {"type": "simulator", "moved_boards": )" + moves + "}}");
    ASSERT_FALSE(r.ok()) << moves;
    EXPECT_EQ(r.status().code(), absl::StatusCode::kInvalidArgument) << moves;
    EXPECT_NE(std::string(r.status().message()).find(expected), std::string::npos)
        << moves << " -> " << r.status().message();
  }
}

}  // namespace
}  // namespace linecal
