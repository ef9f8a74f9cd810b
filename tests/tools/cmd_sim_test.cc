// linecal sim, capture check and lidar topview through the built binary: the reference car
// simulates into a capture that capture check accepts, and broken captures and bad flags are
// refused with exit 2 and a one-line message naming the problem.
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <functional>
#include <nlohmann/json.hpp>
#include <string>

#include "tests/tools/run_linecal.h"

namespace linecal {
namespace {

namespace fs = std::filesystem;
using testing_tools::RunLinecal;

const std::string kRef = std::string(" --station ") + LINECAL_SOURCE_DIR +
                         "/deploy/stations/reference.json --car " + LINECAL_SOURCE_DIR +
                         "/deploy/cars/reference.json";

class SimCliTest : public ::testing::Test {
 protected:
  // One simulated capture shared by the tests (radars and one LiDAR: fast to make).
  static void SetUpTestSuite() {
    dir_ = new fs::path(fs::path(testing::TempDir()) /
                        ("cli_sim_capture_" + std::to_string(::getpid())));
    fs::remove_all(*dir_);
    const auto run = RunLinecal(
        "sim" + kRef + " --seed 4 --sensors front_camera,bumper_lidar,front_radar --json --out " +
        dir_->string());
    ASSERT_EQ(run.exit_code, 0) << run.err;
    const nlohmann::json j = nlohmann::json::parse(run.out);
    EXPECT_EQ(j["sensors"].size(), 3u);
    EXPECT_EQ(j["seed"], 4);
    // Progress goes to stderr, one line per sensor.
    EXPECT_NE(run.err.find("sim: [3/3] front_radar"), std::string::npos) << run.err;
  }
  static void TearDownTestSuite() {
    fs::remove_all(*dir_);
    delete dir_;
  }

  // A copy of the capture to break.
  fs::path Copy(const std::string& name) {
    const fs::path c = fs::path(testing::TempDir()) / name;
    fs::remove_all(c);
    fs::copy(*dir_, c, fs::copy_options::recursive);
    return c;
  }
  static void EditManifest(const fs::path& c, const std::function<void(nlohmann::json&)>& edit) {
    std::ifstream in(c / "manifest.json");
    nlohmann::json j = nlohmann::json::parse(in);
    edit(j);
    std::ofstream(c / "manifest.json") << j.dump(2);
  }

  static fs::path* dir_;
};
fs::path* SimCliTest::dir_ = nullptr;

TEST_F(SimCliTest, CaptureCheckAcceptsTheSimulatedCapture) {
  const auto run = RunLinecal("capture check --json " + dir_->string());
  ASSERT_EQ(run.exit_code, 0) << run.err;
  const nlohmann::json j = nlohmann::json::parse(run.out);
  EXPECT_EQ(j["valid"], true);
  EXPECT_EQ(j["origin"], "simulator");
  EXPECT_EQ(j["sensors"][0]["name"], "front_camera");
  EXPECT_EQ(j["sensors"][0]["frames"], 1);
  EXPECT_EQ(j["sensors"][1]["packets"], true);
  EXPECT_EQ(j["sensors"][2]["can_log"], true);
  EXPECT_TRUE(fs::exists(*dir_ / "ground_truth.json"));
}

TEST_F(SimCliTest, MissingFieldIsNamed) {
  const fs::path c = Copy("cli_missing_field");
  EditManifest(c, [](nlohmann::json& j) { j.erase("aligner"); });
  const auto run = RunLinecal("capture check " + c.string());
  EXPECT_EQ(run.exit_code, 2);
  EXPECT_EQ(run.err,
            "linecal capture check: " + (c / "manifest.json").string() + ": aligner: missing\n");
}

TEST_F(SimCliTest, WrongTypeIsNamed) {
  const fs::path c = Copy("cli_wrong_type");
  EditManifest(c, [](nlohmann::json& j) { j["sensors"][0]["frames"][0]["t_ns"] = 1.5; });
  const auto run = RunLinecal("capture check " + c.string());
  EXPECT_EQ(run.exit_code, 2);
  EXPECT_NE(run.err.find("sensors[0].frames[0].t_ns: expected a whole number, got 1.5"),
            std::string::npos)
      << run.err;
}

TEST_F(SimCliTest, UnknownBoardIsNamed) {
  const fs::path c = Copy("cli_unknown_board");
  std::ifstream in(c / "station.json");
  nlohmann::json j = nlohmann::json::parse(in);
  in.close();
  j["boards"][0]["type"] = "dartboard";
  std::ofstream(c / "station.json") << j.dump();
  const auto run = RunLinecal("capture check " + c.string());
  EXPECT_EQ(run.exit_code, 2);
  EXPECT_NE(run.err.find("station.json: boards[0].type: unknown board type 'dartboard'"),
            std::string::npos)
      << run.err;
}

TEST_F(SimCliTest, CorruptFrameIsNamed) {
  const fs::path c = Copy("cli_corrupt_frame");
  std::ofstream(c / "front_camera/frame-000000.png", std::ios::trunc) << "not a png";
  const auto run = RunLinecal("capture check " + c.string());
  EXPECT_EQ(run.exit_code, 2);
  EXPECT_NE(run.err.find("sensors[0].frames[0]: "), std::string::npos) << run.err;
}

TEST_F(SimCliTest, TopviewDrawsTheScan) {
  const fs::path png = fs::path(testing::TempDir()) / "topview.png";
  const auto run =
      RunLinecal("lidar topview --pcd " + (*dir_ / "bumper_lidar/scan-000000.pcd").string() +
                 " --size 200 --out " + png.string());
  ASSERT_EQ(run.exit_code, 0) << run.err;
  EXPECT_GT(fs::file_size(png), 100u);
  EXPECT_EQ(RunLinecal("lidar topview --pcd /nonexistent.pcd --out " + png.string()).exit_code, 2);
}

TEST(SimCliBadInputTest, BadFlagsAreRefused) {
  const std::string out = (fs::path(testing::TempDir()) / "cli_never").string();
  auto run = RunLinecal("sim" + kRef + " --out " + out + " --noise lots");
  EXPECT_EQ(run.exit_code, 2);
  EXPECT_EQ(run.err, "linecal sim: --noise: 'lots' is not a number\n");
  run = RunLinecal("sim" + kRef + " --out " + out + " --gamma 9");
  EXPECT_EQ(run.exit_code, 2);
  EXPECT_NE(run.err.find("camera.gamma"), std::string::npos) << run.err;
  run = RunLinecal("sim" + kRef + " --out " + out + " --sensors periscope");
  EXPECT_EQ(run.exit_code, 2);
  EXPECT_EQ(run.err, "linecal sim: car model 'reference' has no sensor 'periscope'\n");
  run = RunLinecal(std::string("sim --station /nonexistent.json --car ") + LINECAL_SOURCE_DIR +
                   "/deploy/cars/reference.json --out " + out);
  EXPECT_EQ(run.exit_code, 2);
  EXPECT_NE(run.err.find("/nonexistent.json"), std::string::npos);
  run = RunLinecal("sim --out " + out);
  EXPECT_EQ(run.exit_code, 2);
  EXPECT_EQ(run.err, "linecal sim: missing --station\n");
}

}  // namespace
}  // namespace linecal
