// linecal eval station through the built binary, reduced (2 cars, 1 or 2 frames per sensor) on
// the reference station and car: every sensor of the reference car is solved in every car,
// every planned target is found in every frame, the errors are within the accuracy bars of
// docs/acceptance.md, and the JSON carries every field with sane values; where the evaluation
// finds a bar missed, the test checks that it says so. Two cars cannot put a 95% coverage
// within 0.93..0.97, so the exit code is 1 (the full run is in docs/solvers.md, "The
// full-physics evaluation"). Bad flags are refused with exit 2, naming the flag.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "tests/tools/run_linecal.h"

namespace linecal {
namespace {

using testing_tools::LinecalRun;
using testing_tools::RunLinecal;

const std::string kReference = testing_tools::ReferenceStationAndCarFlags();

// The accuracy bars of docs/acceptance.md ("Solvers"), p95 angle (degrees) and position (mm).
struct Bars {
  double angle_deg, position_mm;
};
Bars BarsOf(const nlohmann::json& sensor) {
  const std::string name = sensor["sensor"];
  if (name == "roof_lidar") return {0.05, 5.0};    // the Pandar64
  if (name == "bumper_lidar") return {0.1, 10.0};  // the VLP-16
  return {0.02, 10.0};                             // cameras; radars' yaw 0.05 below
}

constexpr char kTwoCars[] = "eval station --json --cars 2 --seed 1 --frames-min 1 --frames-max 2";

// The whole car's run, shared by the tests (a minute of rendering and solving).
class EvalStationCliTest : public testing::Test {
 protected:
  static void SetUpTestSuite() { whole_car_ = new LinecalRun(RunLinecal(kTwoCars + kReference)); }
  static void TearDownTestSuite() {
    delete whole_car_;
    whole_car_ = nullptr;
  }
  static const LinecalRun* whole_car_;
};
const LinecalRun* EvalStationCliTest::whole_car_ = nullptr;

TEST_F(EvalStationCliTest, ReferenceCarOnTheReferenceStation) {
  const LinecalRun& run = *whole_car_;
  ASSERT_EQ(run.exit_code, 1) << run.err;
  EXPECT_NE(run.err.find("eval station: car 2 of 2"), std::string::npos) << run.err;
  const nlohmann::json r = nlohmann::json::parse(run.out);
  EXPECT_EQ(r["cars"], 2);
  EXPECT_EQ(r["frames_min"], 1);
  EXPECT_EQ(r["frames_max"], 2);
  EXPECT_EQ(r["lidar_free_running"], true);
  EXPECT_EQ(r["radar_cycles"], 50);
  EXPECT_EQ(r["meets_bars"], false);
  ASSERT_EQ(r["sensors"].size(), 10u);  // every sensor of the reference car
  int radars = 0;
  for (const nlohmann::json& s : r["sensors"]) {
    const std::string name = s["sensor"];
    SCOPED_TRACE(name);
    EXPECT_EQ(s["cars"], 2);
    EXPECT_EQ(s["solved"], 2);
    // Every solved car gets pass or fail, or neither when within 2σ of a tolerance edge.
    EXPECT_EQ(s["verdicts"].get<int>() + s["undecided_near_edge"].get<int>(), 2);
    EXPECT_EQ(s["wrong_verdicts_beyond_1sigma_of_edge"], 0);
    EXPECT_GT(s["error_over_sigma_min"].get<double>(), 0.0);
    EXPECT_LE(s["error_over_sigma_min"].get<double>(), s["error_over_sigma_max"].get<double>());
    EXPECT_GE(s["coverage95_min"].get<double>(), 0.0);
    EXPECT_LE(s["coverage95_max"].get<double>(), 1.0);
    ASSERT_FALSE(s["targets"].empty());
    for (const nlohmann::json& t : s["targets"]) {
      SCOPED_TRACE(t["target"].get<std::string>());
      EXPECT_GT(t["looked_for"].get<int>(), 0);
      EXPECT_EQ(t["found"], t["looked_for"]);
      EXPECT_TRUE(t["miss_reasons"].empty());
    }
    EXPECT_TRUE(s["all_targets_found"].get<bool>());
    if (s["kind"] == "radar") {
      ++radars;
      const double yaw95 = s["yaw_p95_abs_error_deg"].get<double>();
      EXPECT_EQ(s["meets_accuracy_bars"].get<bool>(), yaw95 <= 0.05);
      // The ARS408 meets its 0.05 degree bar; the ESRs, with the radar up to 1 cm off its
      // nominal position, are where docs/acceptance.md says that bar is not met yet.
      if (name == "front_radar") {
        EXPECT_LE(yaw95, 0.05);
      }
      EXPECT_FALSE(s.contains("pitch_error_over_sigma"));  // the yaw alone is measured
      continue;
    }
    const Bars bars = BarsOf(s);
    EXPECT_TRUE(s["meets_accuracy_bars"].get<bool>());
    for (const char* k : {"yaw", "pitch", "roll"}) {
      EXPECT_LE(s[std::string(k) + "_p95_abs_error_deg"].get<double>(), bars.angle_deg) << k;
      EXPECT_GT(s[std::string(k) + "_error_over_sigma"].get<double>(), 0.0) << k;
    }
    for (const char* k : {"x", "y", "z"})
      EXPECT_LE(s[std::string(k) + "_p95_abs_error_mm"].get<double>(), bars.position_mm) << k;
  }
  EXPECT_EQ(radars, 3);
}

// --sensors evaluates a subset whose rows are, field for field, those of the whole car's run:
// every sensor draws from its own random streams.
TEST_F(EvalStationCliTest, ASubsetOfSensorsGivesTheWholeCarsRows) {
  const LinecalRun run = RunLinecal(
      std::string(kTwoCars) + " --sensors bumper_lidar,front_radar,surround_rear" + kReference);
  ASSERT_EQ(run.exit_code, 1) << run.err;
  const nlohmann::json subset = nlohmann::json::parse(run.out);
  EXPECT_EQ(subset["sensors_selected"],
            nlohmann::json({"bumper_lidar", "front_radar", "surround_rear"}));
  ASSERT_EQ(whole_car_->exit_code, 1) << whole_car_->err;
  const nlohmann::json whole = nlohmann::json::parse(whole_car_->out);
  EXPECT_TRUE(whole["sensors_selected"].empty());
  std::vector<std::string> names;
  for (const nlohmann::json& row : subset["sensors"]) {
    names.push_back(row["sensor"]);
    for (const nlohmann::json& full : whole["sensors"]) {
      if (full["sensor"] == row["sensor"]) {
        EXPECT_EQ(row, full) << row["sensor"];
      }
    }
  }
  // In the car model's order, whatever the flag's.
  EXPECT_EQ(names, (std::vector<std::string>{"surround_rear", "bumper_lidar", "front_radar"}));
}

// The corner radars' yaw σ over 1,000 cars (radars alone: seconds). Their σ carries pitch and
// roll within the tolerance; drawn within 1.5x it, as the angles the other sensors measure,
// the coverage was 0.909 and 0.918.
TEST(EvalStationCliRadarTest, CornerRadarSigmaHoldsOverAThousandCars) {
  const LinecalRun run =
      RunLinecal("eval station --json --cars 1000 --sensors corner_radar_left,corner_radar_right" +
                 kReference);
  ASSERT_NE(run.exit_code, 2) << run.err;
  const nlohmann::json r = nlohmann::json::parse(run.out);
  ASSERT_EQ(r["sensors"].size(), 2u);
  for (const nlohmann::json& s : r["sensors"]) {
    SCOPED_TRACE(s["sensor"].get<std::string>());
    EXPECT_EQ(s["solved"], 1000);
    EXPECT_GE(s["yaw_error_over_sigma"].get<double>(), 0.8);
    EXPECT_LE(s["yaw_error_over_sigma"].get<double>(), 1.25);
    EXPECT_GE(s["yaw_coverage95"].get<double>(), 0.93);
    EXPECT_LE(s["yaw_coverage95"].get<double>(), 0.97);
    EXPECT_LE(s["yaw_p95_abs_error_deg"].get<double>(), 0.05);
    EXPECT_EQ(s["wrong_verdicts_beyond_1sigma_of_edge"], 0);
  }
}

// --per-car writes one line per car and sensor whose numbers give the table's: each line's
// error/σ is (estimate − truth) / σ, and over the cars the RMS error over the RMS σ and the
// share within 1.96σ are the summary's error/σ and coverage. A radar's unmeasured components
// are null.
TEST(EvalStationCliPerCarTest, LinesGiveTheSummarysFigures) {
  const std::string path = ::testing::TempDir() + "/eval_station_per_car.jsonl";
  const LinecalRun run =
      RunLinecal("eval station --json --cars 20 --sensors bumper_lidar,front_radar --per-car " +
                 path + kReference);
  ASSERT_NE(run.exit_code, 2) << run.err;
  const nlohmann::json summary = nlohmann::json::parse(run.out);
  std::ifstream in(path);
  std::vector<nlohmann::json> lines;
  for (std::string text; std::getline(in, text);) lines.push_back(nlohmann::json::parse(text));
  ASSERT_EQ(lines.size(), 40u);
  const char* names[6] = {"yaw", "pitch", "roll", "x", "y", "z"};
  std::array<double, 6> sum_e2{}, sum_s2{}, covered{};
  for (size_t k = 0; k < lines.size(); ++k) {
    const nlohmann::json& l = lines[k];
    EXPECT_EQ(l["car"], static_cast<int>(k / 2));
    ASSERT_EQ(l["sensor"], k % 2 == 0 ? "bumper_lidar" : "front_radar");
    ASSERT_TRUE(l["solved"].get<bool>()) << l.dump();
    EXPECT_GE(l["frames"].get<int>(), 1);
    EXPECT_LE(l["frames"].get<int>(), 10);
    for (int i = 0; i < 6; ++i) {
      ASSERT_TRUE(l["truth"][i].is_number()) << l.dump();
      if (k % 2 == 1 && i > 0) {  // a radar measures its yaw alone
        EXPECT_TRUE(l["estimate"][i].is_null() && l["sigma"][i].is_null()) << l.dump();
        continue;
      }
      const double e = l["estimate"][i].get<double>() - l["truth"][i].get<double>();
      const double sigma = l["sigma"][i].get<double>();
      EXPECT_NEAR(l["error_over_sigma"][i].get<double>(), e / sigma,
                  1e-9 * (1 + std::abs(e / sigma)));
      if (k % 2 == 1) continue;
      sum_e2[i] += e * e;
      sum_s2[i] += sigma * sigma;
      covered[i] += std::abs(e) <= 1.96 * sigma;
    }
  }
  const nlohmann::json& lidar = summary["sensors"][0];
  ASSERT_EQ(lidar["sensor"], "bumper_lidar");
  for (int i = 0; i < 6; ++i) {
    SCOPED_TRACE(names[i]);
    const std::string k = names[i];
    EXPECT_NEAR(lidar[k + "_error_over_sigma"].get<double>(), std::sqrt(sum_e2[i] / sum_s2[i]),
                1e-6);
    EXPECT_NEAR(lidar[k + "_coverage95"].get<double>(), covered[i] / 20.0, 1e-12);
  }
  const LinecalRun bad =
      RunLinecal("eval station --cars 1 --per-car /no/such/dir/cars.jsonl" + kReference);
  EXPECT_EQ(bad.exit_code, 2);
  EXPECT_NE(bad.err.find("--per-car: cannot write /no/such/dir/cars.jsonl"), std::string::npos)
      << bad.err;
}

TEST(EvalStationCliFlagsTest, BadFlagsExitTwoNamingTheFlag) {
  for (const std::string flag : {"--frames-min 0", "--frames-max 101", "--range-noise-min-m -1",
                                 "--position-error-m 1", "--threads 0", "--cars 0", "--noise -1"}) {
    const LinecalRun run = RunLinecal("eval station " + flag + kReference);
    EXPECT_EQ(run.exit_code, 2) << flag;
    EXPECT_NE(run.err.find(flag.substr(0, flag.find(' '))), std::string::npos) << run.err;
  }
  const LinecalRun order = RunLinecal("eval station --frames-min 3 --frames-max 2" + kReference);
  EXPECT_EQ(order.exit_code, 2);
  EXPECT_NE(order.err.find("--frames-max"), std::string::npos) << order.err;
  const LinecalRun unknown = RunLinecal("eval station --sensors bumper_lidar,no_such" + kReference);
  EXPECT_EQ(unknown.exit_code, 2);
  EXPECT_NE(unknown.err.find("has no sensor 'no_such'"), std::string::npos) << unknown.err;
  const LinecalRun missing = RunLinecal("eval station --station /no/such.json --car /no/car.json");
  EXPECT_EQ(missing.exit_code, 2);
  EXPECT_NE(missing.err.find("/no/such.json"), std::string::npos) << missing.err;
}

}  // namespace
}  // namespace linecal
