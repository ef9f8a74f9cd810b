// Issue 19's station bar, through the built binary with the detectors in the loop: the
// reference car with a strongly distorting front camera (k1 -0.35, k2 0.12, as real wide-angle
// front cameras have) is rendered by `linecal sim` and calibrated by `linecal calibrate`; the
// mounting must be within the camera bars of docs/acceptance.md (0.02 degrees, 10 mm) and the
// station's front boards found.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

#include "tests/tools/json_file.h"
#include "tests/tools/run_linecal.h"

namespace linecal {
namespace {

namespace fs = std::filesystem;
using testing_tools::ReadJson;
using testing_tools::RunLinecal;

// docs/acceptance.md, camera bars.
constexpr double kAngleBarDeg = 0.02;
constexpr double kPositionBarM = 0.010;

// The reference car with the front camera's k1, k2 replaced, written into `dir` with the
// LiDAR angle file it names (the car file's relative paths are relative to the file).
fs::path WriteStrongLensCar(const fs::path& dir) {
  const fs::path cars = fs::path(LINECAL_SOURCE_DIR) / "deploy/cars";
  nlohmann::json car = ReadJson(cars / "reference.json");
  bool replaced = false;
  for (nlohmann::json& s : car.at("sensors")) {
    if (s.at("name") != "front_camera") continue;
    s.at("intrinsics")["k1"] = -0.35;
    s.at("intrinsics")["k2"] = 0.12;
    replaced = true;
  }
  EXPECT_TRUE(replaced);
  fs::copy_file(cars / "Pandar64.csv", dir / "Pandar64.csv", fs::copy_options::overwrite_existing);
  const fs::path path = dir / "car_k1_035.json";
  std::ofstream(path) << car.dump(1);
  return path;
}

TEST(CalibrateStrongLensTest, FrontCameraWithK1Minus035CalibratesWithinTheBars) {
  const fs::path dir =
      fs::path(testing::TempDir()) / ("calibrate_strong_lens_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  const fs::path car = WriteStrongLensCar(dir);
  for (int seed : {1, 2, 3}) {
    SCOPED_TRACE("seed " + std::to_string(seed));
    const fs::path capture = dir / ("capture_" + std::to_string(seed));
    const auto sim =
        RunLinecal("sim --station " + std::string(LINECAL_SOURCE_DIR) +
                   "/deploy/stations/reference.json --car " + car.string() + " --seed " +
                   std::to_string(seed) + " --sensors front_camera --noise 2 --blur 0.5 --out " +
                   capture.string());
    ASSERT_EQ(sim.exit_code, 0) << sim.err;
    const auto run = RunLinecal("calibrate --json --capture " + capture.string());
    ASSERT_EQ(run.exit_code, 0) << run.out << run.err;
    const nlohmann::json s = nlohmann::json::parse(run.out).at("sensors").at(0);
    EXPECT_EQ(s.at("verdict"), "pass");
    const nlohmann::json error =
        ReadJson(capture / "ground_truth.json").at("sensors").at(0).at("mounting_error");
    const char* angles[3] = {"yaw_deg", "pitch_deg", "roll_deg"};
    const char* position[3] = {"x_m", "y_m", "z_m"};
    for (int i = 0; i < 3; ++i) {
      EXPECT_NEAR(s.at("deviation").at(angles[i]).get<double>(),
                  error.at("ypr_deg").at(i).get<double>(), kAngleBarDeg)
          << angles[i];
      EXPECT_NEAR(s.at("deviation").at(position[i]).get<double>(),
                  error.at("xyz_m").at(i).get<double>(), kPositionBarM)
          << position[i];
    }
    // The boards the front camera calibrates from, found through the lens (bumper_lidar_right
    // too, from what front_vertical leaves of it: issue 20).
    for (const nlohmann::json& b : s.at("boards")) {
      EXPECT_EQ(b.at("frames_found").get<int>(), 1) << b.at("board") << " " << b.at("reason");
    }
    EXPECT_GE(s.at("features_used").get<int>(), 140);
    EXPECT_LT(s.at("residual_rms").get<double>(), 0.2);
  }
  fs::remove_all(dir);
}

}  // namespace
}  // namespace linecal
