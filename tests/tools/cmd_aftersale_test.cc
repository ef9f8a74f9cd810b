// linecal sim lanes + linecal aftersale through the built binary: a rendered lane scene of
// the reference car's front camera (pinhole with distortion) and rear camera (fisheye,
// looking backward) at known mountings is calibrated from its input file or the same values as
// flags; the JSON fields, the PNGs and the exported toolbox files are checked against the
// truth, and bad input ends with exit 2 and a message naming the problem.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

#include "station/io/image_io.h"
#include "tests/tools/json_file.h"
#include "tests/tools/run_linecal.h"

namespace linecal {
namespace {

namespace fs = std::filesystem;
using testing_tools::ReadJson;
using testing_tools::RunLinecal;

const std::string kCar =
    std::string(" --car ") + LINECAL_SOURCE_DIR + "/deploy/cars/reference.json";

std::string Pair(const nlohmann::json& uv) {
  return std::to_string(uv[0].get<double>()) + "," + std::to_string(uv[1].get<double>());
}

class AftersaleCliTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new fs::path(fs::path(testing::TempDir()) /
                        ("cli_aftersale_" + std::to_string(::getpid())));
    fs::remove_all(*dir_);
    const auto run =
        RunLinecal("sim lanes" + kCar +
                   " --camera front_camera --ypr-deg 0.8,2.1,-0.6 --xyz-m 1.9,0.05,1.35 "
                   "--noise 2 --json --out " +
                   (*dir_ / "front").string());
    ASSERT_EQ(run.exit_code, 0) << run.err;
    ASSERT_EQ(nlohmann::json::parse(run.out)["truth"]["camera"], "front_camera");
  }
  static void TearDownTestSuite() {
    fs::remove_all(*dir_);
    delete dir_;
  }
  static fs::path Front() { return *dir_ / "front"; }
  // The input file's values as flags.
  static std::string Flags() {
    const nlohmann::json in = ReadJson(Front() / "aftersale.json");
    const nlohmann::json& k = in["intrinsics"];
    std::string d;
    for (const auto& v : k["distortion"]) {
      if (!d.empty()) d += ",";
      d += std::to_string(v.get<double>());
    }
    return " --image " + (Front() / "front_camera.png").string() + " --lane " +
           Pair(in["lanes"][0][0]) + "," + Pair(in["lanes"][0][1]) + " --lane " +
           Pair(in["lanes"][1][0]) + "," + Pair(in["lanes"][1][1]) + " --roll-line " +
           Pair(in["roll_line"][0]) + "," + Pair(in["roll_line"][1]) + " --camera-height-m 1.35" +
           " --longitudinal-offset-m 1.9 --lateral-offset-m 0.05 --fx " +
           std::to_string(k["fx"].get<double>()) + " --fy " +
           std::to_string(k["fy"].get<double>()) + " --cx " +
           std::to_string(k["cx"].get<double>()) + " --cy " +
           std::to_string(k["cy"].get<double>()) + " --distortion " + d;
  }
  static void ExpectTruth(const nlohmann::json& j, const fs::path& scene) {
    const nlohmann::json truth = ReadJson(scene / "ground_truth.json");
    EXPECT_LT(std::hypot(j["vanishing_point_px"][0].get<double>() -
                             truth["vanishing_point_px"][0].get<double>(),
                         j["vanishing_point_px"][1].get<double>() -
                             truth["vanishing_point_px"][1].get<double>()),
              0.5);
    for (int i = 0; i < 3; ++i) {
      EXPECT_NEAR(
          std::remainder(j["ypr_deg"][i].get<double>() - truth["ypr_deg"][i].get<double>(), 360.0),
          0.0, 0.05)
          << i;
    }
  }
  static fs::path* dir_;
};
fs::path* AftersaleCliTest::dir_ = nullptr;

TEST_F(AftersaleCliTest, InputFileGivesTheTrueMountingPicturesAndExport) {
  const fs::path out = *dir_ / "out", exp = *dir_ / "export";
  const auto run = RunLinecal("aftersale --input " + (Front() / "aftersale.json").string() +
                              " --json --out " + out.string() + " --export " + exp.string());
  ASSERT_EQ(run.exit_code, 0) << run.err;
  const nlohmann::json j = nlohmann::json::parse(run.out);
  ExpectTruth(j, Front());
  EXPECT_EQ(j["roll_source"], "roll_line");
  EXPECT_EQ(j["image_size"], nlohmann::json({1920, 1080}));
  EXPECT_NEAR(j["T_car_camera"]["xyz_m"][1].get<double>(), 0.05, 1e-12);
  const nlohmann::json& c = j["distance_check"];
  EXPECT_EQ(c["verdict"], "pass");
  EXPECT_NEAR(c["measured_distance_m"].get<double>(), 15.0, 0);
  EXPECT_NEAR(c["computed_distance_m"].get<double>(), 15.0, 0.15);  // 1%
  // The flat formula on this pose reads long by its small-angle approximation, < 1% here.
  ASSERT_EQ(j["flat_formula"].size(), 4u);
  EXPECT_EQ(j["flat_formula"][0]["distance_m"], 5.0);
  EXPECT_NEAR(j["flat_formula"][0]["flat_formula_m"].get<double>(), 5.0, 0.05);

  // The pictures, at the image's size and the bird's-eye view's (16 x 40 m at 20 px/m).
  absl::StatusOr<Image8> overlay = ReadImage8(j["overlay_png"].get<std::string>());
  ASSERT_TRUE(overlay.ok()) << overlay.status();
  EXPECT_EQ(overlay->width, 1920);
  EXPECT_EQ(overlay->height, 1080);
  absl::StatusOr<Image8> birdseye = ReadImage8((out / "front_camera-birdseye.png").string());
  ASSERT_TRUE(birdseye.ok()) << birdseye.status();
  EXPECT_EQ(birdseye->width, 320);
  EXPECT_EQ(birdseye->height, 800);
  // The left lane line 1.70 m left of the camera (1.75 m from the lane centre, camera at
  // y = 0.05) is bright paint in the bird's-eye view, 12 m ahead: column (8 - 1.7) * 20 (off
  // the grid lines, every metre and every 5 m).
  EXPECT_GT(birdseye->at(126, (43 - 12) * 20), 150);
  EXPECT_LT(birdseye->at(150, (43 - 12) * 20), 100);  // the road between the lines

  // The toolbox's files, with the real values.
  ASSERT_EQ(j["export"].size(), 3u);
  const nlohmann::json cal =
      ReadJson(exp / "front_camera-calibration.json")["front_camera_calibration"];
  EXPECT_EQ(cal["param"]["vanishing_point"]["vanishing_pt_x"], j["vanishing_point_px"][0]);
  EXPECT_EQ(cal["param"]["vanishing_point"]["vanishing_pt_y"], j["vanishing_point_px"][1]);
  EXPECT_EQ(cal["param"]["h_matrix"]["data"], j["h_matrix"]);
  EXPECT_EQ(cal["param"]["h_matrix"]["rows"], 3);
  // h_matrix takes the undistorted image to the ground: the vanishing point goes to infinity
  // (w = 0) and the homography's inverse.
  const nlohmann::json& h = j["h_matrix"];
  const double u = j["vanishing_point_px"][0], v = j["vanishing_point_px"][1];
  const double w = h[2][0].get<double>() * u + h[2][1].get<double>() * v + h[2][2].get<double>();
  EXPECT_NEAR(w, 0, 1e-9);
  const nlohmann::json intr =
      ReadJson(exp / "front_camera-intrinsic.json")["front_camera_calib"]["param"];
  EXPECT_EQ(intr["cam_K"]["data"],
            nlohmann::json({{1400.0, 0, 962.3}, {0, 1400.0, 541.8}, {0, 0, 1}}));
  EXPECT_EQ(intr["cam_dist"]["data"], nlohmann::json({{-0.12, 0.05, 0.0004, -0.0002, 0.0}}));
  EXPECT_EQ(intr["img_dist_w"], 1920);
  const nlohmann::json ext =
      ReadJson(exp / "front_camera-to-car_center-extrinsic.json")["front_camera_car_center_calib"];
  EXPECT_EQ(ext["target_sensor_name"], "car_center");
  const nlohmann::json& t = ext["param"]["sensor_calib"]["data"];
  for (int i = 0; i < 16; ++i) EXPECT_EQ(t[i / 4][i % 4], j["T_car_camera"]["matrix"][i]) << i;
  EXPECT_NEAR(t[0][2].get<double>(), 1.0, 1e-3);  // the optical axis along x_car: not identity
  EXPECT_NEAR(t[2][3].get<double>(), 1.35, 1e-12);
}

TEST_F(AftersaleCliTest, FlagsGiveTheSameResultAsTheFile) {
  const auto file = RunLinecal("aftersale --json --input " + (Front() / "aftersale.json").string());
  const auto flags = RunLinecal("aftersale --json" + Flags());
  ASSERT_EQ(file.exit_code, 0) << file.err;
  ASSERT_EQ(flags.exit_code, 0) << flags.err;
  const nlohmann::json a = nlohmann::json::parse(file.out), b = nlohmann::json::parse(flags.out);
  for (int i = 0; i < 3; ++i)
    EXPECT_NEAR(a["ypr_deg"][i].get<double>(), b["ypr_deg"][i].get<double>(), 1e-6);
  ExpectTruth(b, Front());
  EXPECT_FALSE(b.contains("distance_check"));
}

TEST_F(AftersaleCliTest, DistanceBeyondTheToleranceFails) {
  const auto run = RunLinecal("aftersale" + Flags() + " --marked-point " +
                              Pair(ReadJson(Front() / "aftersale.json")["marked_point"]["uv_px"]) +
                              " --measured-distance-m 15.6 --tolerance-percent 2");
  EXPECT_EQ(run.exit_code, 1) << run.err;
  EXPECT_NE(run.out.find("-3.85% (tolerance 2.00%): FAIL"), std::string::npos) << run.out;
}

TEST_F(AftersaleCliTest, FourMarkersAndARearFisheye) {
  const fs::path markers = *dir_ / "markers";
  ASSERT_EQ(RunLinecal("sim lanes" + kCar +
                       " --camera front_camera --ypr-deg -0.4,1.2,0.3 --markers-m 7,22 "
                       "--no-lane-lines --out " +
                       markers.string())
                .exit_code,
            0);
  auto run = RunLinecal("aftersale --json --input " + (markers / "aftersale.json").string());
  ASSERT_EQ(run.exit_code, 0) << run.err;
  ExpectTruth(nlohmann::json::parse(run.out), markers);

  const fs::path rear = *dir_ / "rear";
  ASSERT_EQ(RunLinecal("sim lanes" + kCar +
                       " --camera surround_rear --ypr-deg 179.2,18.5,-0.7 --points-m 3,10 "
                       "--roll-line-m 4 --marked-point-m 6 --out " +
                       rear.string())
                .exit_code,
            0);
  run = RunLinecal("aftersale --json --out " + (rear / "out").string() + " --input " +
                   (rear / "aftersale.json").string());
  ASSERT_EQ(run.exit_code, 0) << run.err;
  const nlohmann::json j = nlohmann::json::parse(run.out);
  ExpectTruth(j, rear);
  EXPECT_NEAR(j["distance_check"]["error_percent"].get<double>(), 0, 1.0);
  EXPECT_TRUE(fs::exists(rear / "out" / "surround_rear-birdseye.png"));
}

TEST_F(AftersaleCliTest, BadInputIsRefusedByName) {
  const std::string base = " --image " + (Front() / "front_camera.png").string() +
                           " --camera-height-m 1.35 --fx 1400 --fy 1400";
  struct Case {
    std::string args, message;
  };
  const Case cases[] = {
      {base + " --lane 500,900,600,300 --lane 900,900,1000.5,300",
       "parallel lines: the lane lines are parallel"},
      {base + " --lane 580,200,880,420 --lane 1380,200,1080,420",
       "lanes[0][0] (580.0, 200.0) is above the horizon"},
      {" --image " + (Front() / "front_camera.png").string() +
           " --fx 1400 --fy 1400 --lane 580,795,884,565 --lane "
           "1380,805,1079,567",
       "camera_height_m: missing (--camera-height-m or the input file's camera_height_m)"},
      {" --image " + (Front() / "front_camera.png").string() +
           " --camera-height-m 1.35 --fy 1400 --lane 580,795,884,565 "
           "--lane 1380,805,1079,567",
       "intrinsics.fx: missing (--fx or the input file's intrinsics.fx)"},
      {base, "lanes: missing (--lane, --markers, or the input file's lanes)"},
      {" --image " + (Front() / "aftersale.json").string() +
           " --camera-height-m 1.35 --fx 1400 --fy 1400 --lane 1,2,3,4 "
           "--lane 5,6,7,8",
       "unreadable image: "},
      {base + " --lane 580,795,884,x --lane 1380,805,1079,567", "--lane: 'x' is not a number"},
      {base + " --lane 580,795,884,565 --lane 1380,805,1079,567 --marked-point 960,700",
       "marked_point.measured_distance_m: missing"},
  };
  for (const Case& c : cases) {
    const auto run = RunLinecal("aftersale" + c.args);
    EXPECT_EQ(run.exit_code, 2) << c.args << "\n" << run.err;
    EXPECT_EQ(run.err.rfind("linecal aftersale: " + c.message, 0), 0u) << run.err;
  }
  // A missing field in the input file is named with the file and the field.
  const fs::path bad = *dir_ / "bad.json";
  nlohmann::json in = ReadJson(Front() / "aftersale.json");
  in["intrinsics"]["fx"] = "1400";
  std::ofstream(bad) << in.dump();
  const auto run = RunLinecal("aftersale --input " + bad.string());
  EXPECT_EQ(run.exit_code, 2);
  EXPECT_NE(run.err.find(bad.string() + ": intrinsics.fx"), std::string::npos) << run.err;
  const auto sim =
      RunLinecal("sim lanes" + kCar + " --camera roof_lidar --out " + (*dir_ / "x").string());
  EXPECT_EQ(sim.exit_code, 2);
  EXPECT_NE(sim.err.find("--camera: 'roof_lidar' is not a camera"), std::string::npos) << sim.err;
}

TEST(EvalAftersaleCliTest, SmallRunMeetsTheBarsAtATenthOfAPixel) {
  const auto run = RunLinecal("eval aftersale" + kCar +
                              " --camera front_camera --trials 100 --noise-px 0,0.1 --json");
  ASSERT_EQ(run.exit_code, 0) << run.err;
  const nlohmann::json j = nlohmann::json::parse(run.out);
  ASSERT_EQ(j.size(), 2u);
  EXPECT_EQ(j[0]["trials"], 100);
  EXPECT_EQ(j[0]["refused"], 0);
  EXPECT_LT(j[0]["vanishing_point_p95_px"].get<double>(), 1e-6);  // exact points
  EXPECT_LT(j[0]["ranging_p95_percent"].get<double>(), 1e-6);
  EXPECT_GT(j[1]["vanishing_point_p95_px"].get<double>(), 0.05);  // the noise is there
  EXPECT_LE(j[1]["vanishing_point_p95_px"].get<double>(), 0.5);
  EXPECT_LE(j[1]["yaw_p95_deg"].get<double>(), 0.05);
  EXPECT_LE(j[1]["pitch_p95_deg"].get<double>(), 0.05);
  EXPECT_LE(j[1]["ranging_p95_percent"].get<double>(), 1.0);
  const auto bad = RunLinecal("eval aftersale" + kCar + " --camera front_camera --noise-px 0.1,x");
  EXPECT_EQ(bad.exit_code, 2);
  EXPECT_EQ(bad.err, "linecal eval aftersale: --noise-px: 'x' is not a number\n");
}

}  // namespace
}  // namespace linecal
