// linecal radar calibrate through the built binary: radars of the reference car simulated
// into a capture (linecal sim --sensors ...) are calibrated against ground_truth.json, a
// mounting beyond tolerance fails with exit 1, bad input exits 2. And linecal eval radar.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

#include "tests/tools/run_linecal.h"

namespace linecal {
namespace {

namespace fs = std::filesystem;
using testing_tools::LinecalRun;
using testing_tools::RunLinecal;

const std::string kRef = std::string(" --station ") + LINECAL_SOURCE_DIR +
                         "/deploy/stations/reference.json --car " + LINECAL_SOURCE_DIR +
                         "/deploy/cars/reference.json";
// Estimates within 4 reported σ of the truth (a false failure once in 16,000 per check).
constexpr double kSigmaBound = 4.0;

// Simulates the reference car's radars with 50 cycles and no mounting position error (the
// calibration takes the position as nominal) into a capture; returns its directory.
fs::path Simulate(const std::string& name, int seed, double perturb_angle_deg) {
  const fs::path dir = fs::path(testing::TempDir()) / name;
  fs::remove_all(dir);
  const LinecalRun run = RunLinecal(
      "sim" + kRef + " --seed " + std::to_string(seed) +
      " --sensors front_radar,corner_radar_left --radar-cycles 50 --perturb-offset-m 0" +
      " --perturb-angle-deg " + std::to_string(perturb_angle_deg) + " --out " + dir.string());
  EXPECT_EQ(run.exit_code, 0) << run.err;
  return dir;
}

// The true yaw deviation from nominal (degrees) of a sensor in ground_truth.json.
double TrueYawErrorDeg(const fs::path& dir, const std::string& sensor) {
  std::ifstream in(dir / "ground_truth.json");
  const nlohmann::json truth = nlohmann::json::parse(in);
  for (const nlohmann::json& s : truth["sensors"]) {
    if (s["name"] == sensor) return s["mounting_error"]["ypr_deg"][0].get<double>();
  }
  ADD_FAILURE() << "no ground truth for " << sensor;
  return 0;
}

TEST(RadarCalibrateCliTest, CalibratesSimulatedRadarsAgainstGroundTruth) {
  const fs::path dir = Simulate("radar_cal_capture", 3, 0.5);
  for (const std::string sensor : {"front_radar", "corner_radar_left"}) {
    SCOPED_TRACE(sensor);
    const LinecalRun run =
        RunLinecal("radar calibrate --capture " + dir.string() + " --sensor " + sensor + " --json");
    ASSERT_EQ(run.exit_code, 0) << run.err << run.out;
    const nlohmann::json j = nlohmann::json::parse(run.out);
    EXPECT_EQ(j["sensor"], sensor);
    EXPECT_EQ(j["verdict"], "pass");
    EXPECT_EQ(j["reason"], "");
    EXPECT_EQ(j["cycles"], 50);
    EXPECT_EQ(j["pitch_observable"], false);
    EXPECT_EQ(j["position"], "nominal");
    EXPECT_EQ(j["reflectors_used"], sensor == "front_radar" ? 6 : 3);  // deploy/cars/reference.json
    for (const nlohmann::json& r : j["reflectors"]) EXPECT_EQ(r["status"], "found") << r["id"];
    const double sigma = j["yaw_sigma_deg"].get<double>();
    EXPECT_GT(sigma, 0);
    EXPECT_NEAR(j["yaw_deviation_deg"].get<double>(), TrueYawErrorDeg(dir, sensor),
                kSigmaBound * sigma);
    EXPECT_NEAR(j["yaw_deg"].get<double>() - j["nominal_yaw_deg"].get<double>(),
                j["yaw_deviation_deg"].get<double>(), 1e-9);
    EXPECT_EQ(j["T_car_sensor"].size(), 16u);
  }

  // The table form says what is not observable.
  const LinecalRun text =
      RunLinecal("radar calibrate --capture " + dir.string() + " --sensor corner_radar_left");
  EXPECT_EQ(text.exit_code, 0) << text.err;
  EXPECT_NE(text.out.find("pitch and roll not observable"), std::string::npos) << text.out;
  EXPECT_NE(text.out.find("refl_corner_left_near"), std::string::npos) << text.out;
}

// Mounting errors up to ±3°: seed 8 turns the left corner radar by -1.74°, beyond its 1° yaw
// tolerance (asserted from the ground truth), so the verdict is fail and the exit code 1.
TEST(RadarCalibrateCliTest, OutOfToleranceFails) {
  const fs::path dir = Simulate("radar_cal_capture_bad", 8, 3.0);
  const double truth = TrueYawErrorDeg(dir, "corner_radar_left");
  ASSERT_GT(std::abs(truth), 1.2) << "the seed no longer gives an out-of-tolerance mounting";
  const LinecalRun run = RunLinecal("radar calibrate --capture " + dir.string() +
                                    " --sensor corner_radar_left --json");
  ASSERT_EQ(run.exit_code, 1) << run.err << run.out;
  const nlohmann::json j = nlohmann::json::parse(run.out);
  EXPECT_EQ(j["verdict"], "fail");
  EXPECT_EQ(j["reason"], "yaw_out_of_tolerance");
  EXPECT_NEAR(j["yaw_deviation_deg"].get<double>(), truth,
              kSigmaBound * j["yaw_sigma_deg"].get<double>());
}

TEST(RadarCalibrateCliTest, BadInputExitsTwo) {
  const fs::path dir = Simulate("radar_cal_capture_input", 5, 0.5);
  const std::string capture = " --capture " + dir.string();
  LinecalRun run = RunLinecal("radar calibrate" + capture + " --sensor rear_radar");
  EXPECT_EQ(run.exit_code, 2);
  EXPECT_NE(run.err.find("no sensor 'rear_radar'"), std::string::npos) << run.err;
  run = RunLinecal("radar calibrate" + capture + " --sensor front_camera");
  EXPECT_EQ(run.exit_code, 2);
  EXPECT_NE(run.err.find("not a radar"), std::string::npos) << run.err;
  run = RunLinecal("radar calibrate" + capture + " --sensor corner_radar_right");
  EXPECT_EQ(run.exit_code, 2);
  EXPECT_NE(run.err.find("no CAN log for sensor 'corner_radar_right'"), std::string::npos)
      << run.err;
  run = RunLinecal("radar calibrate --capture /nonexistent/capture --sensor front_radar");
  EXPECT_EQ(run.exit_code, 2);
  run = RunLinecal("radar calibrate --sensor front_radar");
  EXPECT_EQ(run.exit_code, 2);
}

// The evaluation runs end to end: one row per radar model of the reference car, the ESR rows
// within the 0.05° bar already on 40 cars (its p95 over 1,600 runs is 0.023°).
TEST(EvalRadarCliTest, ReportsOneRowPerRadarModel) {
  const LinecalRun run = RunLinecal("eval radar" + kRef + " --cars 40 --seed 3 --json");
  ASSERT_TRUE(run.exit_code == 0 || run.exit_code == 1) << run.err;
  const nlohmann::json j = nlohmann::json::parse(run.out);
  EXPECT_EQ(j["cars"], 40);
  EXPECT_EQ(j["cycles"], 50);
  EXPECT_EQ(j["azimuth_sigma_deg"], 0.1);
  ASSERT_EQ(j["groups"].size(), 2u);
  EXPECT_EQ(j["groups"][0]["group"], "ars408");
  EXPECT_EQ(j["groups"][0]["cars"], 40);
  const nlohmann::json& esr = j["groups"][1];
  EXPECT_EQ(esr["group"], "esr");
  EXPECT_EQ(esr["cars"], 80);  // two corner radars per car
  EXPECT_EQ(esr["calibrated"], 80);
  EXPECT_LE(esr["p95_abs_yaw_error_deg"].get<double>(), 0.05);
  EXPECT_EQ(j["meets_bars"], run.exit_code == 0);

  EXPECT_EQ(RunLinecal("eval radar" + kRef + " --cars 0").exit_code, 2);
  EXPECT_EQ(RunLinecal("eval radar" + kRef + " --position-error-m 2").exit_code, 2);
  EXPECT_EQ(RunLinecal("eval radar" + kRef + " --range-noise-m -0.01").exit_code, 2);
}

}  // namespace
}  // namespace linecal
