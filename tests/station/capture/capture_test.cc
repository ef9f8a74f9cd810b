// The capture format: a written capture reads back equal, and every kind of broken capture
// is refused with a message naming the offending path and field.
#include "station/capture/capture.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <functional>
#include <string>

#include "station/io/image_io.h"
#include "station/model/vin.h"

namespace linecal {
namespace {

namespace fs = std::filesystem;
const std::string kDeploy = std::string(LINECAL_SOURCE_DIR) + "/deploy";
// A VIN with a valid North American check digit (computed by hand from 49 CFR 565).
constexpr char kVin[] = "1M8GDM9AXKP042788";

void WriteBytes(const fs::path& p, const std::string& bytes) {
  fs::create_directories(p.parent_path());
  std::ofstream(p, std::ios::binary) << bytes;
}

class CaptureTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ =
        fs::path(testing::TempDir()) /
        ("capture_" + std::string(testing::UnitTest::GetInstance()->current_test_info()->name()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    absl::StatusOr<StationLayout> st = ReadStationLayout(kDeploy + "/stations/reference.json");
    ASSERT_TRUE(st.ok()) << st.status();
    station_ = std::move(*st);
    absl::StatusOr<CarModel> car = ReadCarModel(kDeploy + "/cars/reference.json");
    ASSERT_TRUE(car.ok()) << car.status();
    car_ = std::move(*car);
    m_.vin = kVin;
    m_.car_model = "reference";
    m_.time_ns = 1763776000000000000;
    m_.origin = "simulator";
    m_.aligner.lateral_offset_m = 0.01;
    // The raw files only need to exist here; their contents are checked by their readers.
    WriteBytes(dir_ / "front_camera/frame-000000.png", "png");
    WriteBytes(dir_ / "roof_lidar/packets.pcap", "pcap");
    WriteBytes(dir_ / "front_radar/can.log", "(0.0) can0 701#00");
    m_.sensors = {
        {"front_camera",
         SensorKind::kCamera,
         {{"front_camera/frame-000000.png", 1763776000000000000}},
         {},
         {}},
        {"roof_lidar",
         SensorKind::kLidar,
         {},
         CaptureFile{"roof_lidar/packets.pcap", 1763776000000000000},
         {}},
        {"front_radar",
         SensorKind::kRadar,
         {},
         {},
         CaptureFile{"front_radar/can.log", 1763776000000000000}},
    };
  }

  // Writes the capture, then applies `edit` to the manifest JSON.
  void WriteWith(const std::function<void(nlohmann::json&)>& edit) {
    ASSERT_TRUE(WriteCapture(dir_.string(), m_, station_, car_).ok());
    std::ifstream in(dir_ / kCaptureManifestFile);
    nlohmann::json j = nlohmann::json::parse(in);
    edit(j);
    std::ofstream(dir_ / kCaptureManifestFile) << j.dump(2);
  }

  // A real, black camera frame of the size the car model gives, for the data checks.
  void WriteRealFrame() {
    const CameraIntrinsics& in = *car_.FindSensor("front_camera")->intrinsics;
    const Image8 image(in.width, in.height);
    ASSERT_TRUE(WritePng8((dir_ / "front_camera/frame-000000.png").string(), image.view()).ok());
  }

  void ExpectError(const std::string& expected) {
    absl::StatusOr<Capture> c = ReadCapture(dir_.string());
    ASSERT_FALSE(c.ok());
    EXPECT_NE(std::string(c.status().message()).find(expected), std::string::npos)
        << c.status().message();
  }

  fs::path dir_;
  StationLayout station_;
  CarModel car_;
  CaptureManifest m_;
};

TEST_F(CaptureTest, WrittenCaptureReadsBack) {
  ASSERT_TRUE(WriteCapture(dir_.string(), m_, station_, car_).ok());
  absl::StatusOr<Capture> c = ReadCapture(dir_.string());
  ASSERT_TRUE(c.ok()) << c.status();
  EXPECT_EQ(c->manifest.vin, kVin);
  EXPECT_EQ(c->manifest.time_ns, 1763776000000000000);
  EXPECT_DOUBLE_EQ(c->manifest.aligner.lateral_offset_m, 0.01);
  ASSERT_EQ(c->manifest.sensors.size(), 3u);
  EXPECT_EQ(c->manifest.sensors[1].packets->path, "roof_lidar/packets.pcap");
  EXPECT_EQ(c->car.sensors.size(), car_.sensors.size());
  EXPECT_EQ(c->station.boards.size(), station_.boards.size());
  // The angle file travelled with the capture.
  const SensorModel* roof = c->car.FindSensor("roof_lidar");
  ASSERT_NE(roof, nullptr);
  EXPECT_EQ(fs::path(roof->angles_file).parent_path(), fs::absolute(dir_).lexically_normal());
  EXPECT_TRUE(fs::exists(roof->angles_file));
}

TEST_F(CaptureTest, MissingManifestIsNotFound) {
  absl::StatusOr<Capture> c = ReadCapture(dir_.string());
  ASSERT_FALSE(c.ok());
  EXPECT_EQ(c.status().code(), absl::StatusCode::kNotFound);
  EXPECT_NE(std::string(c.status().message()).find("manifest.json"), std::string::npos);
}

TEST_F(CaptureTest, MissingFieldIsNamed) {
  WriteWith([](nlohmann::json& j) { j.erase("vin"); });
  ExpectError("manifest.json: vin: missing");
}

TEST_F(CaptureTest, WrongTypeIsNamed) {
  WriteWith([](nlohmann::json& j) { j["time_ns"] = "yesterday"; });
  ExpectError("manifest.json: time_ns: expected a whole number");
}

TEST_F(CaptureTest, BadVinIsNamed) {
  WriteWith([](nlohmann::json& j) { j["vin"] = "1M8GDM9AXKP04278O"; });
  ExpectError("manifest.json: vin: character 17 'O' is not allowed");
}

TEST_F(CaptureTest, NewerVersionIsRefused) {
  WriteWith([](nlohmann::json& j) { j["version"] = 2; });
  ExpectError("version: unsupported version 2");
}

TEST_F(CaptureTest, UnknownSensorIsNamed) {
  WriteWith([](nlohmann::json& j) { j["sensors"][0]["name"] = "rear_camera"; });
  ExpectError("sensors[0].name: car model 'reference' has no sensor 'rear_camera'");
}

TEST_F(CaptureTest, KindMismatchIsNamed) {
  WriteWith([](nlohmann::json& j) { j["sensors"][2]["kind"] = "lidar"; });
  ExpectError("sensors[2].kind: 'lidar' but the car model says 'front_radar' is a radar");
}

TEST_F(CaptureTest, MissingFileIsNamed) {
  WriteWith(
      [](nlohmann::json& j) { j["sensors"][0]["frames"][0]["path"] = "front_camera/nope.png"; });
  ExpectError("sensors[0].frames[0].path: no such file 'front_camera/nope.png'");
}

TEST_F(CaptureTest, PathsCannotEscape) {
  WriteWith([](nlohmann::json& j) { j["sensors"][0]["frames"][0]["path"] = "../../etc/passwd"; });
  ExpectError(
      "sensors[0].frames[0].path: '../../etc/passwd' must be a relative path inside the capture");
  WriteWith([](nlohmann::json& j) { j["sensors"][0]["frames"][0]["path"] = "/etc/passwd"; });
  ExpectError("must be a relative path inside the capture");
}

TEST_F(CaptureTest, RadarWithoutLogIsNamed) {
  WriteWith([](nlohmann::json& j) { j["sensors"][2].erase("can_log"); });
  ExpectError("sensors[2].can_log: missing (a radar needs its CAN log)");
}

TEST_F(CaptureTest, UnknownBoardInStationIsNamed) {
  ASSERT_TRUE(WriteCapture(dir_.string(), m_, station_, car_).ok());
  std::ifstream in(dir_ / kCaptureStationFile);
  nlohmann::json j = nlohmann::json::parse(in);
  j["boards"][3]["type"] = "hexboard";
  std::ofstream(dir_ / kCaptureStationFile) << j.dump();
  ExpectError("station.json: boards[3].type: unknown board type 'hexboard'");
}

TEST_F(CaptureTest, CarModelMismatchIsNamed) {
  WriteWith([](nlohmann::json& j) { j["car_model"] = "sedan"; });
  ExpectError("car_model: 'sedan' but car.json is car model 'reference'");
}

// ---- Symbolic links (issue 21, item 5): a capture cannot point outside itself. ----------
// Each case links a file or folder of the capture to a real file outside it holding a
// "secret", and expects ReadCapture to name the entry and never the secret.

constexpr char kSecret[] = "s3cr3t-token-of-another-service";

class CaptureSymlinkTest : public CaptureTest {
 protected:
  void SetUp() override {
    CaptureTest::SetUp();
    outside_ = dir_.parent_path() / (dir_.filename().string() + "_outside");
    fs::remove_all(outside_);
    fs::create_directories(outside_);
    WriteBytes(outside_ / "secret.txt", kSecret);
  }
  void TearDown() override { fs::remove_all(outside_); }

  void ExpectRefusedWithoutSecret(const std::string& expected) {
    absl::StatusOr<Capture> c = ReadCapture(dir_.string());
    ASSERT_FALSE(c.ok()) << "a capture with a link outside itself was accepted";
    const std::string message(c.status().message());
    EXPECT_NE(message.find(expected), std::string::npos) << message;
    EXPECT_EQ(message.find("s3cr3t"), std::string::npos) << message;
  }

  fs::path outside_;
};

TEST_F(CaptureSymlinkTest, FrameLinkedOutsideIsRefused) {
  ASSERT_TRUE(WriteCapture(dir_.string(), m_, station_, car_).ok());
  fs::remove(dir_ / "front_camera/frame-000000.png");
  fs::create_symlink(outside_ / "secret.txt", dir_ / "front_camera/frame-000000.png");
  ExpectRefusedWithoutSecret(
      "sensors[0].frames[0].path: 'front_camera/frame-000000.png': resolves outside the capture");
}

TEST_F(CaptureSymlinkTest, FolderLinkedOutsideIsRefused) {
  ASSERT_TRUE(WriteCapture(dir_.string(), m_, station_, car_).ok());
  fs::rename(dir_ / "front_camera", outside_ / "front_camera");
  fs::create_directory_symlink(outside_ / "front_camera", dir_ / "front_camera");
  ExpectRefusedWithoutSecret(
      "sensors[0].frames[0].path: 'front_camera/frame-000000.png': resolves outside the capture");
}

TEST_F(CaptureSymlinkTest, ManifestLinkedOutsideIsRefused) {
  ASSERT_TRUE(WriteCapture(dir_.string(), m_, station_, car_).ok());
  fs::rename(dir_ / kCaptureManifestFile, outside_ / kCaptureManifestFile);
  fs::create_symlink(outside_ / kCaptureManifestFile, dir_ / kCaptureManifestFile);
  ExpectRefusedWithoutSecret((dir_ / "manifest.json").string() + ": resolves outside the capture");
}

TEST_F(CaptureSymlinkTest, CanLogLinkedToASecretIsRefused) {
  ASSERT_TRUE(WriteCapture(dir_.string(), m_, station_, car_).ok());
  fs::remove(dir_ / "front_radar/can.log");
  fs::create_symlink(outside_ / "secret.txt", dir_ / "front_radar/can.log");
  ExpectRefusedWithoutSecret(
      "sensors[2].can_log.path: 'front_radar/can.log': resolves outside the capture");
}

// Components are compared, not strings: /tmp/cap_outside is not inside /tmp/cap even though
// its name starts with it.
TEST_F(CaptureSymlinkTest, SiblingWithTheSamePrefixIsOutside) {
  ASSERT_TRUE(dir_.string().size() < outside_.string().size() &&
              outside_.string().rfind(dir_.string(), 0) == 0);
  ASSERT_TRUE(WriteCapture(dir_.string(), m_, station_, car_).ok());
  fs::remove(dir_ / "roof_lidar/packets.pcap");
  fs::create_symlink(outside_ / "secret.txt", dir_ / "roof_lidar/packets.pcap");
  ExpectRefusedWithoutSecret("'roof_lidar/packets.pcap': resolves outside the capture");
}

TEST_F(CaptureSymlinkTest, LinksInsideTheCaptureAreFollowed) {
  ASSERT_TRUE(WriteCapture(dir_.string(), m_, station_, car_).ok());
  fs::rename(dir_ / "front_camera", dir_ / "camera_data");
  fs::create_directory_symlink("camera_data", dir_ / "front_camera");
  absl::StatusOr<Capture> c = ReadCapture(dir_.string());
  EXPECT_TRUE(c.ok()) << c.status();
}

// ---- The input budget (issue 21, item 4) -------------------------------------------------

TEST_F(CaptureTest, ManifestWithTooManyFramesIsRefusedBeforeItsFiles) {
  // 2000 entries of files that do not exist: the count is refused before any is looked at.
  WriteWith([](nlohmann::json& j) {
    nlohmann::json frames = nlohmann::json::array();
    for (int k = 0; k < 2000; ++k) {
      frames.push_back(
          {{"path", "front_camera/f" + std::to_string(k) + ".png"}, {"t_ns", 1763776000000000000}});
    }
    j["sensors"][0]["frames"] = frames;
  });
  ExpectError(
      "sensors[0].frames: 2000 frames exceed the budget of 1000 "
      "(input_budget.max_manifest_frames)");
}

TEST_F(CaptureTest, FileOverTheByteBudgetIsRefusedByReadCapture) {
  ASSERT_TRUE(WriteCapture(dir_.string(), m_, station_, car_).ok());
  InputBudget budget;
  budget.max_file_bytes = 10;
  WriteBytes(dir_ / "roof_lidar/packets.pcap", std::string(11, 'p'));
  absl::StatusOr<Capture> c = ReadCapture(dir_.string(), budget);
  ASSERT_FALSE(c.ok());
  EXPECT_NE(std::string(c.status().message())
                .find("sensors[1].packets.path: 'roof_lidar/packets.pcap': 11 bytes exceed the "
                      "budget of 10 (input_budget.max_file_bytes)"),
            std::string::npos)
      << c.status();
}

TEST_F(CaptureTest, CheckCaptureDataRefusesAGarbageCanLog) {
  ASSERT_TRUE(WriteCapture(dir_.string(), m_, station_, car_).ok());
  WriteRealFrame();
  WriteBytes(dir_ / "front_radar/can.log",
             "(1600000000.000000) can0 701#00\npassword=hunter2 root\n");
  absl::StatusOr<Capture> c = ReadCapture(dir_.string());
  ASSERT_TRUE(c.ok()) << c.status();
  // ReadCapture looks at names and sizes only; the data check parses the log as calibration.
  const absl::Status s = CheckCaptureData(*c);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(std::string(s.message())
                .find("sensors[2].can_log: " + (dir_ / "front_radar/can.log").string() +
                      ":2: expected '(seconds.micros) "
                      "interface ID#DATA', got 2 field(s)"),
            std::string::npos)
      << s;
  EXPECT_EQ(std::string(s.message()).find("hunter2"), std::string::npos) << s;
}

TEST_F(CaptureTest, CheckCaptureDataRefusesATruncatedPcd) {
  m_.sensors[1].frames = {{"roof_lidar/scan-000000.pcd", 1763776000000000000}};
  ASSERT_TRUE(WriteCapture(dir_.string(), m_, station_, car_).ok());
  WriteRealFrame();
  // A header announcing 1000 points of 12 bytes, and 100 bytes of data.
  WriteBytes(dir_ / "roof_lidar/scan-000000.pcd",
             "VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 1000\n"
             "HEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 1000\nDATA binary\n" +
                 std::string(100, '\0'));
  absl::StatusOr<Capture> c = ReadCapture(dir_.string());
  ASSERT_TRUE(c.ok()) << c.status();
  const absl::Status s = CheckCaptureData(*c);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(std::string(s.message())
                .find("sensors[1].frames[0]: " + (dir_ / "roof_lidar/scan-000000.pcd").string() +
                      ": not a readable PCD file (1000 points of 12 bytes do "
                      "not fit the file's 100 bytes of data)"),
            std::string::npos)
      << s;
}

TEST(VinTest, ValidatesCharactersLengthAndCheckDigit) {
  EXPECT_TRUE(ValidateVin(kVin, true).ok());
  EXPECT_EQ(VinCheckDigit(kVin), 'X');
  EXPECT_TRUE(ValidateVin("WVWZZZ1JZXW000001", false).ok());
  EXPECT_EQ(ValidateVin("WVWZZZ1JZXW00000", false).message(), "must have 17 characters, has 16");
  EXPECT_EQ(ValidateVin("WVWZZZ1JZXW00000I", false).message(),
            "character 17 'I' is not allowed (I, O, Q never appear in a VIN)");
  EXPECT_EQ(ValidateVin("wvwzzz1jzxw000001", false).message(),
            "character 1 is not an upper-case letter or digit (0x77)");
  EXPECT_EQ(ValidateVin("1M8GDM9A1KP042788", true).message(),
            "check digit (character 9) is '1', expected 'X'");
}

}  // namespace
}  // namespace linecal
