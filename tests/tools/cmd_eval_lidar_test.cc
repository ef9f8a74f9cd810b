// linecal eval lidar through the built binary, reduced (4 cars, 10 rotations, range noise
// 2 cm) on the reference station and car: the accuracy bars of docs/acceptance.md that the full
// evaluation (docs/lidar-radar.md) meets with room for the p95 of 4 cars (their largest error)
// are asserted here; the VLP-16's normal, which it misses, is checked to be reported missed.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>
#include <string>

#include "tests/tools/run_linecal.h"

namespace linecal {
namespace {

using testing_tools::LinecalRun;
using testing_tools::RunLinecal;

const std::string kReference = std::string(" --station ") + LINECAL_SOURCE_DIR +
                               "/deploy/stations/reference.json --car " + LINECAL_SOURCE_DIR +
                               "/deploy/cars/reference.json";

TEST(EvalLidarCliTest, ReferenceCarOnTheReferenceStation) {
  const LinecalRun run = RunLinecal("eval lidar --json --cars 4 --seed 3" + kReference);
  // Exit 1: the VLP-16's normal p95 misses 0.1 degree (docs/lidar-radar.md), and 4 cars cannot
  // put a 95% coverage within 0.93..0.97.
  ASSERT_EQ(run.exit_code, 1) << run.err;
  const nlohmann::json r = nlohmann::json::parse(run.out);
  ASSERT_EQ(r["lidars"].size(), 2u);
  const nlohmann::json& roof = r["lidars"][0];
  const nlohmann::json& bumper = r["lidars"][1];
  ASSERT_EQ(roof["lidar"], "roof_lidar");
  ASSERT_EQ(bumper["lidar"], "bumper_lidar");
  EXPECT_EQ(roof["rings"], 64);
  EXPECT_EQ(bumper["rings"], 16);
  for (const nlohmann::json* l : {&roof, &bumper}) {
    SCOPED_TRACE((*l)["lidar"].get<std::string>());
    EXPECT_EQ((*l)["cars"], 4);
    EXPECT_EQ((*l)["solved"], 4);
    EXPECT_GT((*l)["ms_per_frame"].get<double>(), 0.0);  // the bar: round_hole_bench
  }
  // The Pandar64 meets every accuracy bar over 200 cars with at least half of it to spare:
  // angles 0.05 degree, positions 5 mm, hole centres 1 cm, normal 0.1 degree.
  for (const char* k : {"yaw", "pitch", "roll"})
    EXPECT_LE(roof[std::string(k) + "_p95_abs_error_deg"].get<double>(), 0.05) << k;
  for (const char* k : {"x", "y", "z"})
    EXPECT_LE(roof[std::string(k) + "_p95_abs_error_mm"].get<double>(), 5.0) << k;
  EXPECT_LE(roof["hole_centre_max_mm"].get<double>(), 10.0);
  EXPECT_LE(roof["normal_p95_deg"].get<double>(), 0.1);
  // The VLP-16: yaw, roll (0.1 degree), x, y, z (10 mm) and hole centres (2 cm). Its pitch also
  // meets 0.1 degree over 200 cars, but at p95 0.075 degree (σ ≈ 0.038): the p95 of 4 cars, near
  // their largest error, passes 0.1 about one run in 25 (this seed's: 0.103), so it is not
  // asserted here.
  for (const char* k : {"yaw", "roll"})
    EXPECT_LE(bumper[std::string(k) + "_p95_abs_error_deg"].get<double>(), 0.1) << k;
  for (const char* k : {"x", "y", "z"})
    EXPECT_LE(bumper[std::string(k) + "_p95_abs_error_mm"].get<double>(), 10.0) << k;
  EXPECT_LE(bumper["hole_centre_max_mm"].get<double>(), 20.0);
  EXPECT_EQ(roof["verdict_agreement"], 1.0);
  EXPECT_EQ(bumper["verdict_agreement"], 1.0);
  EXPECT_FALSE(bumper["meets_bars"].get<bool>());
}

// --free-running: every rotation at its own azimuth phase (docs/lidar-radar.md, "A
// free-running motor"); the JSON says so, and every car is solved.
TEST(EvalLidarCliTest, FreeRunningMotor) {
  const LinecalRun run =
      RunLinecal("eval lidar --json --cars 2 --seed 3 --frames 2 --free-running" + kReference);
  ASSERT_TRUE(run.exit_code == 0 || run.exit_code == 1) << run.err;
  const nlohmann::json r = nlohmann::json::parse(run.out);
  EXPECT_EQ(r["free_running"], true);
  EXPECT_EQ(r["frames"], 2);
  ASSERT_EQ(r["lidars"].size(), 2u);
  for (const nlohmann::json& l : r["lidars"]) EXPECT_EQ(l["solved"], 2) << l["lidar"];
}

TEST(EvalLidarCliTest, BadInputExitsTwo) {
  const LinecalRun run = RunLinecal("eval lidar --station /no/such.json --car /no/car.json");
  EXPECT_EQ(run.exit_code, 2);
  EXPECT_NE(run.err.find("/no/such.json"), std::string::npos) << run.err;
  const LinecalRun frames = RunLinecal("eval lidar --frames 0" + kReference);
  EXPECT_EQ(frames.exit_code, 2);
  EXPECT_NE(frames.err.find("--frames"), std::string::npos) << frames.err;
  const LinecalRun noise = RunLinecal("eval lidar --noise-m -1" + kReference);
  EXPECT_EQ(noise.exit_code, 2);
  EXPECT_NE(noise.err.find("--noise-m"), std::string::npos) << noise.err;
}

}  // namespace
}  // namespace linecal
