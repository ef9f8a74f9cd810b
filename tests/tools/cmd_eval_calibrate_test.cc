// linecal eval calibrate through the built binary, on the reference station and car with the
// docs/acceptance.md settings (corner noise 0.2 px, 1000 cars): the bars the reference layout lets
// each camera reach (docs/solvers.md). The front camera meets every bar; for every camera the
// reported sigma matches the spread and the verdicts agree with the truth.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>
#include <string>

#include "tests/tools/run_linecal.h"

namespace linecal {
namespace {

using testing_tools::LinecalRun;
using testing_tools::RunLinecal;

// The 95% coverage of N cars has a standard error of sqrt(0.95 * 0.05 / N): 1.5% at 200 cars,
// where the 0.93..0.97 bar is +-1.3 standard errors and each component misses it by chance
// with probability ~0.2 (docs/solvers.md); at 1000 cars it is +-2.9 (0.7 s of CPU per 100 cars).
constexpr int kCars = 1000;

TEST(EvalCalibrateCliTest, ReferenceCarOnTheReferenceStation) {
  const LinecalRun run =
      RunLinecal("eval calibrate --json --cars " + std::to_string(kCars) + " --seed 1 --station " +
                 LINECAL_SOURCE_DIR + "/deploy/stations/reference.json --car " +
                 LINECAL_SOURCE_DIR + "/deploy/cars/reference.json");
  // Exit 1: method (b) on surround_front misses its ranging bar on this layout (docs/solvers.md).
  ASSERT_EQ(run.exit_code, 1) << run.err;
  const nlohmann::json r = nlohmann::json::parse(run.out);
  ASSERT_EQ(r["cameras"].size(), 5u);
  for (const nlohmann::json& c : r["cameras"]) {
    SCOPED_TRACE(c["camera"].get<std::string>());
    EXPECT_EQ(c["solved"], kCars);
    EXPECT_EQ(c["verdict_agreement"], 1.0);
    for (const char* k : {"yaw", "pitch", "roll", "x", "y", "z"}) {
      const double ratio = c[std::string(k) + "_error_over_sigma"];
      EXPECT_GT(ratio, 0.8) << k;
      EXPECT_LT(ratio, 1.2) << k;
    }
    // The accuracy bars hold for every camera, the fisheye surround cameras included.
    for (const char* k : {"yaw", "pitch", "roll"})
      EXPECT_LE(c[std::string(k) + "_p95_abs_error_deg"].get<double>(), 0.02) << k;
    for (const char* k : {"x", "y", "z"})
      EXPECT_LE(c[std::string(k) + "_p95_abs_error_mm"].get<double>(), 10.0) << k;
    if (!c["vanishing_point_p95_px"].is_null()) {
      EXPECT_LE(c["vanishing_point_p95_px"].get<double>(), 0.3);
      EXPECT_LE(c["ranging_p95_fraction"].get<double>(), 0.005);
    }
  }
  const nlohmann::json& front = r["cameras"][0];
  ASSERT_EQ(front["camera"], "front_camera");
  EXPECT_TRUE(front["meets_bars"].get<bool>()) << front.dump(2);
  EXPECT_LE(front["vanishing_point_p95_px"].get<double>(), 0.3);
  EXPECT_LE(front["ranging_p95_fraction"].get<double>(), 0.005);
  for (const char* k : {"yaw", "pitch", "roll"})
    EXPECT_LE(front[std::string(k) + "_p95_abs_error_deg"].get<double>(), 0.02) << k;
  for (const char* k : {"x", "y", "z"})
    EXPECT_LE(front[std::string(k) + "_p95_abs_error_mm"].get<double>(), 10.0) << k;
  for (const char* k : {"yaw", "pitch", "roll", "x", "y", "z"}) {
    const double coverage = front[std::string(k) + "_coverage95"];
    EXPECT_GE(coverage, 0.93) << k;
    EXPECT_LE(coverage, 0.97) << k;
  }
  // The seed formulas (method (b), the board method) against the extrinsic: 0.5 px, 0.5%
  // (docs/acceptance.md), on every car; the toolbox's small-angle ranging formula misses the
  // 0.5% on pitched cameras (docs/solvers.md), so it is reported, not judged.
  EXPECT_EQ(front["board_method_cars"], kCars);
  EXPECT_TRUE(front["board_method_meets_bars"].get<bool>());
  EXPECT_LE(front["board_method_vanishing_point_p95_px"].get<double>(), 0.5);
  EXPECT_LE(front["board_method_ranging_p95_fraction"].get<double>(), 0.005);
  EXPECT_GT(front["board_method_toolbox_ranging_p95_fraction"].get<double>(), 0.005);
  EXPECT_EQ(front["vertical_roll_cars"], kCars);
}

TEST(EvalCalibrateCliTest, BadInputExitsTwo) {
  const LinecalRun run = RunLinecal("eval calibrate --station /no/such.json --car /no/car.json");
  EXPECT_EQ(run.exit_code, 2);
  EXPECT_NE(run.err.find("/no/such.json"), std::string::npos) << run.err;
  const LinecalRun frames =
      RunLinecal(std::string("eval calibrate --frames 0 --station ") + LINECAL_SOURCE_DIR +
                 "/deploy/stations/reference.json --car " + LINECAL_SOURCE_DIR +
                 "/deploy/cars/reference.json");
  EXPECT_EQ(frames.exit_code, 2);
  EXPECT_NE(frames.err.find("--frames"), std::string::npos) << frames.err;
}

}  // namespace
}  // namespace linecal
