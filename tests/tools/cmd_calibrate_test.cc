// linecal calibrate through the built binary: a simulated capture of the reference car's
// front camera and front radar is calibrated; the JSON results document has the fields of
// docs/interfaces.md, and the estimates agree with ground_truth.json within their reported sigma.
#include <gtest/gtest.h>
#include <unistd.h>

#include <array>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <string>

#include "station/camera/camera_model.h"
#include "station/capture/capture.h"
#include "tests/support/crafted_files.h"
#include "tests/support/scoped_path.h"
#include "tests/tools/json_file.h"
#include "tests/tools/run_linecal.h"

namespace linecal {
namespace {

namespace fs = std::filesystem;
using testing_support::ScopedPath;
using testing_tools::LinecalRun;
using testing_tools::ReadJson;
using testing_tools::RunLinecal;

const std::string kRef = std::string(" --station ") + LINECAL_SOURCE_DIR +
                         "/deploy/stations/reference.json --car " + LINECAL_SOURCE_DIR +
                         "/deploy/cars/reference.json";
// Estimates within 4 reported sigma of the truth (a false failure once in 16,000 per check).
constexpr double kSigmaBound = 4.0;

class CalibrateCliTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    // Per process: ctest runs each test of the suite in its own process, in parallel.
    dir_ = fs::path(testing::TempDir()) / ("calibrate_cli_capture_" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    const LinecalRun sim = RunLinecal(
        "sim" + kRef + " --seed 3 --sensors front_camera,front_radar --noise 2 --blur 0.5" +
        " --out " + dir_.string());
    ASSERT_EQ(sim.exit_code, 0) << sim.err;
  }
  static void TearDownTestSuite() { fs::remove_all(dir_); }
  static fs::path dir_;
};
fs::path CalibrateCliTest::dir_;

TEST_F(CalibrateCliTest, JsonResultsAgreeWithTheGroundTruth) {
  const LinecalRun run = RunLinecal("calibrate --json --capture " + dir_.string());
  ASSERT_EQ(run.exit_code, 0) << run.out << run.err;
  const nlohmann::json r = nlohmann::json::parse(run.out);
  const nlohmann::json truth = ReadJson(dir_ / "ground_truth.json");
  const nlohmann::json manifest = ReadJson(dir_ / "manifest.json");
  EXPECT_EQ(r["vin"], manifest["vin"]);
  EXPECT_EQ(r["car_model"], "reference");
  EXPECT_EQ(r["verdict"], "pass");
  ASSERT_EQ(r["sensors"].size(), 2u);

  for (const nlohmann::json& s : r["sensors"]) {
    const std::string name = s["name"];
    SCOPED_TRACE(name);
    EXPECT_EQ(s["verdict"], "pass");
    EXPECT_EQ(s["reason"], "");
    ASSERT_EQ(s["T_car_sensor"].size(), 16u);  // 4x4, row-major
    nlohmann::json error;
    for (const nlohmann::json& t : truth["sensors"]) {
      if (t["name"] == name) error = t["mounting_error"];
    }
    ASSERT_FALSE(error.is_null());
    const char* angles[3] = {"yaw_deg", "pitch_deg", "roll_deg"};
    const char* position[3] = {"x_m", "y_m", "z_m"};
    for (int i = 0; i < 3; ++i) {
      if (s["deviation"][angles[i]].is_null()) continue;  // not observable by this sensor
      const double sigma = s["sigma"][angles[i]];
      EXPECT_GT(sigma, 0) << angles[i];
      EXPECT_NEAR(s["deviation"][angles[i]].get<double>(), error["ypr_deg"][i].get<double>(),
                  kSigmaBound * sigma)
          << angles[i];
    }
    for (int i = 0; i < 3; ++i) {
      if (s["deviation"][position[i]].is_null()) continue;
      const double sigma = s["sigma"][position[i]];
      EXPECT_NEAR(s["deviation"][position[i]].get<double>(), error["xyz_m"][i].get<double>(),
                  kSigmaBound * sigma)
          << position[i];
    }
    if (s["kind"] == "camera") {
      EXPECT_GE(s["features_used"].get<int>(), 20);
      EXPECT_LT(s["residual_rms"].get<double>(), 0.2);  // pixels: a render with noise 2 grey levels
      ASSERT_EQ(s["vanishing_point_px"].size(), 2u);
      ASSERT_EQ(s["ground_homography"].size(), 9u);
      ASSERT_EQ(s["ranging"].size(), 4u);
      // The flat-ground formula D = h fy / (v - vp_v) treats the pixel's angle below the
      // horizon as if the camera had no pitch: tan(a) - tan(-pitch) for tan(a + pitch). For
      // this camera (pitched down 1.7 deg) that is 0.7% at 5 m, shrinking as 1/D: within
      // 0.5% from 10 m on, and within 1% at 5 m.
      for (const nlohmann::json& c : s["ranging"]) {
        const double d = c["true_distance_m"];
        EXPECT_NEAR(c["measured_distance_m"].get<double>(), d, (d < 10 ? 0.01 : 0.005) * d) << d;
      }
      // The seed formulas with the real detectors: method (b) from the rendered chessboard
      // within the acceptance bars of method (a), and the vertical board's roll beside the
      // pose's.
      const nlohmann::json& b = s["board_method"];
      ASSERT_TRUE(b["valid"].get<bool>()) << b.dump();
      EXPECT_LT(b["vanishing_point_disagreement_px"].get<double>(), 0.5);
      ASSERT_EQ(b["ranging_disagreement"].size(), 4u);
      for (const nlohmann::json& c : b["ranging_disagreement"])
        EXPECT_LT(c["fraction"].get<double>(), 0.005);
      ASSERT_EQ(b["ground_points_px"].size(), 4u);
      const nlohmann::json& roll = s["roll_from_vertical_board"];
      ASSERT_TRUE(roll["valid"].get<bool>()) << roll.dump();
      EXPECT_EQ(roll["pose_roll_deg"].get<double>(), s["mounting"]["roll_deg"].get<double>());
      EXPECT_LT(std::abs(roll["difference_deg"].get<double>()), 0.1);
    } else {
      // A radar measures yaw only: pitch, roll and the position stay nominal (null).
      EXPECT_TRUE(s["deviation"]["pitch_deg"].is_null());
      EXPECT_TRUE(s["sigma"]["x_m"].is_null());
      EXPECT_EQ(s["features_used"], 6);  // the six front reflectors
    }
  }
}

// The roof LiDAR (Pandar64) from 10 simulated rotations: both round-hole boards found in the
// clouds, the mounting within 4 reported sigma of the truth. (The 16-ring bumper LiDAR is
// not asserted: its hole centres' in-plane sigma is underestimated, docs/lidar-radar.md.)
TEST(CalibrateLidarCliTest, RoofLidarAgreesWithTheGroundTruth) {
  const ScopedPath scratch("calibrate_cli_lidar");
  const fs::path& dir = scratch.path();
  const LinecalRun sim = RunLinecal(
      "sim" + kRef + " --seed 5 --sensors roof_lidar --lidar-rotations 10 --out " + dir.string());
  ASSERT_EQ(sim.exit_code, 0) << sim.err;
  const LinecalRun run = RunLinecal("calibrate --json --capture " + dir.string());
  ASSERT_TRUE(run.exit_code == 0 || run.exit_code == 1) << run.err;
  const nlohmann::json r = nlohmann::json::parse(run.out);
  ASSERT_EQ(r["sensors"].size(), 1u);
  const nlohmann::json& s = r["sensors"][0];
  EXPECT_EQ(s["kind"], "lidar");
  EXPECT_EQ(s["features_used"], 10);  // 5 hole centres on each of the two boards
  for (const nlohmann::json& b : s["boards"]) EXPECT_EQ(b["reason"], "") << b["board"];
  const nlohmann::json truth = ReadJson(dir / "ground_truth.json");
  const nlohmann::json& error = truth["sensors"][0]["mounting_error"];
  const char* angles[3] = {"yaw_deg", "pitch_deg", "roll_deg"};
  const char* position[3] = {"x_m", "y_m", "z_m"};
  for (int i = 0; i < 3; ++i) {
    EXPECT_NEAR(s["deviation"][angles[i]].get<double>(), error["ypr_deg"][i].get<double>(),
                kSigmaBound * s["sigma"][angles[i]].get<double>())
        << angles[i];
    EXPECT_NEAR(s["deviation"][position[i]].get<double>(), error["xyz_m"][i].get<double>(),
                kSigmaBound * s["sigma"][position[i]].get<double>())
        << position[i];
  }
  EXPECT_EQ(s["verdict"], "pass") << s["message"];
}

// The rear fisheye from its renders, as issue 20 measured it. The pitch with the ArUco board:
// in the raw image the lens bends the ArUco markers' sides and the board fit's dilation takes
// up the bending, which put the pitch +0.0027..+0.0039 degrees off on every seed
// (docs/solvers.md, "The rear ArUco board through the fisheye"); found in the board's
// perspective view, the errors are -0.0007..+0.0012 and of both signs. The position with the
// two checkers beside the car: in the raw image their corners came out 0.028 px towards the
// image centre, which put x +0.066..+0.092 mm (2.5-3.7 sigma) and z +0.060..+0.072 mm off on
// every seed (docs/solvers.md, "Camera sigma on the full-physics evaluation"); from their
// views, x -0.016..+0.008 mm and z -0.002..+0.008 mm.
TEST(CalibrateFisheyeCliTest, SurroundRearHasNoRawFisheyeBias) {
  const ScopedPath scratch("calibrate_cli_rear");
  const fs::path& base = scratch.path();
  double sum_deg = 0;
  constexpr int kSeeds = 5;
  for (int seed = 1; seed <= kSeeds; ++seed) {
    SCOPED_TRACE(seed);
    const fs::path dir = base / std::to_string(seed);
    fs::remove_all(dir);
    const LinecalRun sim = RunLinecal(
        "sim" + kRef + " --seed " + std::to_string(seed) +
        " --sensors surround_rear --frames 3 --noise 2 --blur 0.5 --out " + dir.string());
    ASSERT_EQ(sim.exit_code, 0) << sim.err;
    const LinecalRun run = RunLinecal("calibrate --json --capture " + dir.string());
    ASSERT_EQ(run.exit_code, 0) << run.out << run.err;
    const nlohmann::json s = nlohmann::json::parse(run.out)["sensors"][0];
    for (const nlohmann::json& b : s["boards"]) EXPECT_EQ(b["frames_found"], 3) << b["board"];
    const nlohmann::json error =
        ReadJson(dir / "ground_truth.json")["sensors"][0]["mounting_error"];
    const double error_deg =
        s["deviation"]["pitch_deg"].get<double>() - error["ypr_deg"][1].get<double>();
    // Twice the largest error measured after each fix, under the smallest one before it.
    EXPECT_LT(std::abs(error_deg), 0.0025);
    EXPECT_LT(std::abs(s["deviation"]["x_m"].get<double>() - error["xyz_m"][0].get<double>()),
              0.032e-3);
    EXPECT_LT(std::abs(s["deviation"]["z_m"].get<double>() - error["xyz_m"][2].get<double>()),
              0.016e-3);
    sum_deg += error_deg;
  }
  // The pitch bias itself: the mean of the five was +0.0034 degrees, it is +0.0003 now.
  EXPECT_LT(std::abs(sum_deg / kSeeds), 0.0012);
}

TEST_F(CalibrateCliTest, TableNamesEverySensor) {
  const LinecalRun run = RunLinecal("calibrate --capture " + dir_.string());
  ASSERT_EQ(run.exit_code, 0) << run.err;
  EXPECT_NE(run.out.find("front_camera"), std::string::npos);
  EXPECT_NE(run.out.find("front_radar"), std::string::npos);
  EXPECT_NE(run.out.find(": pass"), std::string::npos) << run.out;
}

TEST_F(CalibrateCliTest, BadInputExitsTwoNamingTheProblem) {
  const LinecalRun missing = RunLinecal("calibrate --capture /no/such/capture");
  EXPECT_EQ(missing.exit_code, 2);
  EXPECT_NE(missing.err.find("/no/such/capture"), std::string::npos) << missing.err;
  const LinecalRun usage = RunLinecal("calibrate --json");
  EXPECT_EQ(usage.exit_code, 2);
  EXPECT_NE(usage.err.find("--capture"), std::string::npos) << usage.err;
}

// --report: a PNG per camera, of the image's size, with the drawing where the results put it:
// a ring around a reprojected chessboard corner (magenta) and around the vanishing point on
// the horizon (cyan), both computed here from the JSON pose, the layout and the aligner.
TEST_F(CalibrateCliTest, ReportDrawsTheModelAndTheHorizonWhereThePosePutsThem) {
  const ScopedPath scratch("calibrate_cli_report");
  const fs::path& report = scratch.path();
  const LinecalRun run =
      RunLinecal("calibrate --json --capture " + dir_.string() + " --report " + report.string());
  ASSERT_EQ(run.exit_code, 0) << run.err;
  const nlohmann::json r = nlohmann::json::parse(run.out);
  const absl::StatusOr<Capture> capture = ReadCapture(dir_.string());
  ASSERT_TRUE(capture.ok()) << capture.status();
  int cameras = 0;
  for (const nlohmann::json& s : r["sensors"]) {
    if (s["kind"] != "camera") {
      EXPECT_FALSE(fs::exists(report / (s["name"].get<std::string>() + ".png")));
      continue;
    }
    ++cameras;
    const SensorModel& sensor = *capture->car.FindSensor(s["name"]);
    const cv::Mat png =
        cv::imread((report / (sensor.name + ".png")).string(), cv::IMREAD_COLOR);  // BGR
    ASSERT_FALSE(png.empty()) << sensor.name;
    EXPECT_EQ(png.cols, sensor.intrinsics->width);
    EXPECT_EQ(png.rows, sensor.intrinsics->height);
    Eigen::Matrix4d T;
    for (int i = 0; i < 16; ++i) T(i / 4, i % 4) = s["T_car_sensor"][i];
    const Rigid3d T_car_camera(Eigen::Matrix3d(T.topLeftCorner<3, 3>()),
                               Eigen::Vector3d(T.topRightCorner<3, 1>()));
    const CameraModel camera = *CameraModel::Create(*sensor.intrinsics);
    auto rgb_at = [&](const Eigen::Vector2d& uv, int du) {
      const cv::Vec3b bgr = png.at<cv::Vec3b>(static_cast<int>(std::lround(uv.y())),
                                              static_cast<int>(std::lround(uv.x())) + du);
      return std::array<int, 3>{bgr[2], bgr[1], bgr[0]};
    };
    const StationBoard& board = *capture->station.FindBoard("front_chessboard");
    const Rigid3d T_camera_board =
        (capture->manifest.aligner.T_station_car() * T_car_camera).Inverse() *
        board.T_station_board;
    Eigen::Vector2d corner;
    ASSERT_TRUE(
        camera.Project(T_camera_board * Eigen::Vector3d(board.board.features()[0].p_board.x(),
                                                        board.board.features()[0].p_board.y(), 0),
                       &corner));
    EXPECT_EQ(rgb_at(corner, 6), (std::array<int, 3>{255, 0, 255})) << corner.transpose();
    Eigen::Vector2d vp;
    ASSERT_TRUE(camera.Project(T_car_camera.Inverse().RotationMatrix().col(0), &vp));
    EXPECT_EQ(rgb_at(vp, 8), (std::array<int, 3>{0, 255, 255})) << vp.transpose();
    // The image itself is grey: a pixel off every drawing keeps r = g = b.
    const std::array<int, 3> plain = rgb_at(Eigen::Vector2d(sensor.intrinsics->width - 3, 3), 0);
    EXPECT_EQ(plain[0], plain[1]);
    EXPECT_EQ(plain[1], plain[2]);
  }
  EXPECT_EQ(cameras, 1);

  // A report path that is a file: exit 2 naming it, before any work.
  const fs::path file = report / "front_camera.png";
  const LinecalRun bad =
      RunLinecal("calibrate --capture " + dir_.string() + " --report " + file.string());
  EXPECT_EQ(bad.exit_code, 2);
  EXPECT_NE(bad.err.find("--report " + file.string()), std::string::npos) << bad.err;
}

// A camera whose frames were lost gives that sensor an error with the file named, and the
// radar is still calibrated.
TEST_F(CalibrateCliTest, UnreadableFrameIsThatSensorsError) {
  const ScopedPath scratch("calibrate_cli_corrupt");
  const fs::path& copy = scratch.path();
  fs::copy(dir_, copy, fs::copy_options::recursive);
  const fs::path frame = copy / "front_camera" / "frame-000000.png";
  ASSERT_TRUE(fs::exists(frame));
  std::ofstream(frame, std::ios::trunc) << "not a png";
  const LinecalRun run = RunLinecal("calibrate --json --capture " + copy.string());
  EXPECT_EQ(run.exit_code, 1) << run.err;
  const nlohmann::json r = nlohmann::json::parse(run.out);
  EXPECT_EQ(r["verdict"], "error");
  for (const nlohmann::json& s : r["sensors"]) {
    if (s["name"] == "front_camera") {
      EXPECT_EQ(s["verdict"], "error");
      EXPECT_EQ(s["reason"], "data_unreadable");
      EXPECT_NE(s["message"].get<std::string>().find("frame-000000.png"), std::string::npos)
          << s["message"];
    } else {
      EXPECT_EQ(s["verdict"], "pass") << s["name"];
    }
  }
}

// Issue 21, item 4: capture check and calibrate read frames through the same readers under
// the same budget, so a 74-byte PNG claiming 16384 x 16384 is refused by both, with the same
// message, and neither decodes it.
TEST_F(CalibrateCliTest, FrameOverTheBudgetIsRefusedByCheckAndCalibrateAlike) {
  const ScopedPath scratch("calibrate_cli_huge");
  const fs::path& copy = scratch.path();
  fs::copy(dir_, copy, fs::copy_options::recursive);
  const fs::path frame = copy / "front_camera" / "frame-000000.png";
  ASSERT_TRUE(fs::exists(frame));
  std::ofstream(frame, std::ios::binary | std::ios::trunc) << testing_support::HugeClaimPng();
  const std::string refusal = frame.string() +
                              ": 268435456 pixels exceed the budget of 50000000 "
                              "(input_budget.max_image_pixels)";
  const LinecalRun check = RunLinecal("capture check " + copy.string());
  EXPECT_EQ(check.exit_code, 2) << check.err;
  EXPECT_EQ(check.err, "linecal capture check: " + (copy / "manifest.json").string() +
                           ": sensors[0].frames[0]: " + refusal + "\n");
  const LinecalRun run = RunLinecal("calibrate --json --capture " + copy.string());
  EXPECT_EQ(run.exit_code, 1) << run.err;
  const nlohmann::json r = nlohmann::json::parse(run.out);
  for (const nlohmann::json& s : r["sensors"]) {
    if (s["name"] != "front_camera") continue;
    EXPECT_EQ(s["reason"], "data_unreadable");
    EXPECT_EQ(s["message"], refusal);
  }
}

// The budget from the command line: both commands take the same --max-* options.
TEST_F(CalibrateCliTest, BudgetFlagsApplyToCheckAndCalibrate) {
  const fs::path frame = dir_ / "front_camera" / "frame-000000.png";
  const cv::Mat image = cv::imread(frame.string(), cv::IMREAD_UNCHANGED);
  ASSERT_FALSE(image.empty());
  const std::string refusal = frame.string() + ": " + std::to_string(image.total()) +
                              " pixels exceed the budget of 100 (input_budget.max_image_pixels)";
  const LinecalRun check = RunLinecal("capture check --max-image-pixels 100 " + dir_.string());
  EXPECT_EQ(check.exit_code, 2) << check.err;
  EXPECT_NE(check.err.find(refusal), std::string::npos) << check.err;
  const LinecalRun run =
      RunLinecal("calibrate --json --max-image-pixels 100 --capture " + dir_.string());
  EXPECT_EQ(run.exit_code, 1) << run.err;
  const nlohmann::json r = nlohmann::json::parse(run.out);
  for (const nlohmann::json& s : r["sensors"]) {
    if (s["name"] == "front_camera") {
      EXPECT_EQ(s["message"], refusal);
    }
  }
  const LinecalRun bad = RunLinecal("calibrate --max-can-lines 0 --capture " + dir_.string());
  EXPECT_EQ(bad.exit_code, 2);
  EXPECT_EQ(bad.err, "linecal calibrate: --max-can-lines '0': must be an integer >= 1\n");
}

// A garbage CAN log passed capture check before (it only looked at frames); now the log is
// parsed as calibrate parses it, and the message names file and line without quoting it.
TEST_F(CalibrateCliTest, CaptureCheckParsesTheCanLog) {
  const ScopedPath scratch("calibrate_cli_can");
  const fs::path& copy = scratch.path();
  fs::copy(dir_, copy, fs::copy_options::recursive);
  const fs::path log = copy / "front_radar" / "can.log";
  ASSERT_TRUE(fs::exists(log));
  std::ofstream(log, std::ios::binary | std::ios::trunc) << "AWS_SECRET_KEY=abcdefghijklmnop\n";
  const LinecalRun check = RunLinecal("capture check " + copy.string());
  EXPECT_EQ(check.exit_code, 2) << check.err;
  EXPECT_EQ(check.err, "linecal capture check: " + (copy / "manifest.json").string() +
                           ": sensors[1].can_log: " + log.string() +
                           ":1: expected '(seconds.micros) interface ID#DATA', got 1 field(s)\n");
}

}  // namespace
}  // namespace linecal
