// linecal plan and linecal plan check through the built binary: the plan for the reference
// car in the reference floor is verified with the simulator and the real detection and
// calibration (every sensor that the detectors can serve passes, and its measured sigma is
// within ±30% of the predicted one); deliberately broken layouts get exactly the right
// reasons; bad input exits 2 naming the file, field or flag.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <nlohmann/json.hpp>
#include <set>
#include <string>

#include "tests/tools/json_file.h"
#include "tests/tools/run_linecal.h"

namespace linecal {
namespace {

namespace fs = std::filesystem;
using testing_tools::LinecalRun;
using testing_tools::ReadJson;
using testing_tools::RunLinecal;

const std::string kCar = std::string(LINECAL_SOURCE_DIR) + "/deploy/cars/reference.json";
const std::string kFloor =
    std::string(LINECAL_SOURCE_DIR) + "/deploy/stations/reference-floor.json";
// The chessboard detector's corner noise on the simulator's renders at --noise 2 --blur 0.5
// (docs/planner.md, measured from the residuals of `linecal calibrate` on seeds 6..8).
// The fisheye cameras' boards are found in resampled perspective views, whose corners are less
// noisy: 0.012 px is the mean over their σ on seeds 6..10 (docs/planner.md).
constexpr char kCornerNoise[] = " --corner-noise-px 0.04 --fisheye-corner-noise-px 0.012";
constexpr char kFisheyes[] = "surround_front,surround_rear,surround_left,surround_right";

void WriteJson(const fs::path& path, const nlohmann::json& j) {
  std::ofstream out(path);
  out << j.dump(1);
}

class PlanCliTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    // Per process: ctest runs each test of the suite in its own process, in parallel.
    dir_ = fs::path(testing::TempDir()) / ("plan_cli_" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    const LinecalRun plan = RunLinecal("plan --car " + kCar + " --floor " + kFloor + kCornerNoise +
                                       " --no-regions --json --out " + (dir_ / "plan").string());
    ASSERT_EQ(plan.exit_code, 0) << plan.out << plan.err;
    plan_ = nlohmann::json::parse(plan.out);
  }
  static void TearDownTestSuite() { fs::remove_all(dir_); }

  // `plan check` of the planned car against a copy of the planned layout changed by `edit`:
  // the reasons of every sensor that is not calibratable.
  static std::map<std::string, std::vector<std::string>> CheckEdited(
      const std::function<void(nlohmann::json&)>& edit, const std::string& noise = kCornerNoise,
      int* exit_code = nullptr) {
    nlohmann::json station = ReadJson(dir_ / "plan" / "station.json");
    edit(station);
    const fs::path path = dir_ / "edited.json";
    WriteJson(path, station);
    const LinecalRun run =
        RunLinecal("plan check --json --station " + path.string() + " --car " +
                   (dir_ / "plan" / "car.json").string() + " --floor " + kFloor + noise);
    if (exit_code) *exit_code = run.exit_code;
    std::map<std::string, std::vector<std::string>> out;
    const nlohmann::json j = nlohmann::json::parse(run.out);
    for (const nlohmann::json& s : j["sensors"]) {
      if (!s["calibratable"].get<bool>())
        out[s["name"]] = s["reasons"].get<std::vector<std::string>>();
    }
    return out;
  }

  static nlohmann::json& Board(nlohmann::json& station, const std::string& id) {
    for (nlohmann::json& b : station["boards"]) {
      if (b["id"] == id) return b;
    }
    ADD_FAILURE() << "no board " << id;
    return station;
  }

  static fs::path dir_;
  static nlohmann::json plan_;
};
fs::path PlanCliTest::dir_;
nlohmann::json PlanCliTest::plan_;

TEST_F(PlanCliTest, EverySensorIsPlannedAndTheFilesAreWritten) {
  EXPECT_EQ(plan_["format"], "linecal.plan");
  EXPECT_TRUE(plan_["calibratable"].get<bool>());
  ASSERT_EQ(plan_["sensors"].size(), 10u);
  for (const nlohmann::json& s : plan_["sensors"]) {
    SCOPED_TRACE(s["name"].get<std::string>());
    EXPECT_TRUE(s["calibratable"].get<bool>());
    EXPECT_LE(s["uncertainty_ratio"].get<double>(), 1.0);
    EXPECT_GT(s["predicted_sigma"]["yaw_deg"].get<double>(), 0);
  }
  // The layout is a station file and the car a car file: `plan check` reads them back.
  const LinecalRun check =
      RunLinecal("plan check --station " + (dir_ / "plan" / "station.json").string() + " --car " +
                 (dir_ / "plan" / "car.json").string() + " --floor " + kFloor + kCornerNoise);
  EXPECT_EQ(check.exit_code, 0) << check.out << check.err;
  for (const std::string name :
       {"birdseye", "side_front_camera", "side_roof_lidar", "side_front_radar"}) {
    std::ifstream svg(dir_ / "plan" / (name + ".svg"));
    std::string head(4, '\0');
    svg.read(head.data(), 4);
    EXPECT_EQ(head, "<svg") << name;
    std::ifstream png(dir_ / "plan" / (name + ".png"), std::ios::binary);
    std::string sig(8, '\0');
    png.read(sig.data(), 8);
    EXPECT_EQ(sig, std::string("\x89PNG\r\n\x1a\n", 8)) << name;
  }
}

// The car's mounting errors within ±0.25° (half the LiDARs' tolerance), the range over which
// the LiDAR prediction averages the detector's sigma (docs/planner.md: at the tolerance's
// edge the VLP-16's sigma varies up to 1.6x). Every sensor of the car, rendered and calibrated
// by the real detectors and solvers, passes; its σ is within ±30% of the prediction — for the
// fisheye cameras the mean σ of three cars, as theirs spreads ±19% (1 SD) from car to car
// where the others' stays within ±10% (docs/planner.md).
TEST_F(PlanCliTest, SimulatedPlanPassesWithinThirtyPercentOfThePredictedSigma) {
  std::map<std::string, nlohmann::json> predicted;
  for (const nlohmann::json& s : plan_["sensors"]) predicted[s["name"]] = s["predicted_sigma"];
  std::map<std::pair<std::string, std::string>, std::vector<double>> fisheye_ratios;
  int compared = 0;
  for (const int seed : {11, 16, 17}) {
    SCOPED_TRACE(seed);
    const fs::path capture = dir_ / ("capture_" + std::to_string(seed));
    // The first car is the whole car; the two more only its fisheye cameras.
    const std::string sensors = seed == 11 ? "" : std::string(" --sensors ") + kFisheyes;
    const LinecalRun sim = RunLinecal(
        "sim --station " + (dir_ / "plan" / "station.json").string() + " --car " +
        (dir_ / "plan" / "car.json").string() + sensors + " --seed " + std::to_string(seed) +
        " --noise 2 --blur 0.5 --perturb-angle-deg 0.25 --out " + capture.string());
    ASSERT_EQ(sim.exit_code, 0) << sim.err;
    const LinecalRun cal = RunLinecal("calibrate --json --capture " + capture.string());
    ASSERT_EQ(cal.exit_code, 0) << cal.out << cal.err;
    const nlohmann::json results = nlohmann::json::parse(cal.out);
    ASSERT_EQ(results["sensors"].size(), seed == 11 ? 10u : 4u);
    for (const nlohmann::json& s : results["sensors"]) {
      const std::string name = s["name"];
      SCOPED_TRACE(name);
      EXPECT_EQ(s["verdict"], "pass") << s["reason"] << " " << s["message"];
      const bool fisheye = std::string(kFisheyes).find(name) != std::string::npos;
      for (const char* k : {"yaw_deg", "pitch_deg", "roll_deg", "x_m", "y_m", "z_m"}) {
        if (s["sigma"][k].is_null()) {
          EXPECT_TRUE(predicted[name][k].is_null()) << k;  // the same components observed
          continue;
        }
        const double ratio = s["sigma"][k].get<double>() / predicted[name][k].get<double>();
        if (fisheye) {
          fisheye_ratios[{name, k}].push_back(ratio);
        } else {
          EXPECT_NEAR(ratio, 1.0, 0.30)
              << k << ": measured " << s["sigma"][k] << ", predicted " << predicted[name][k];
          ++compared;
        }
      }
    }
  }
  // Six components of the front camera and two LiDARs, yaw of three radars.
  EXPECT_EQ(compared, 3 * 6 + 3);
  ASSERT_EQ(fisheye_ratios.size(), 4u * 6);
  for (const auto& [key, ratios] : fisheye_ratios) {
    ASSERT_EQ(ratios.size(), 3u);
    const double mean = (ratios[0] + ratios[1] + ratios[2]) / 3;
    EXPECT_NEAR(mean, 1.0, 0.30) << key.first << " " << key.second << ": measured/predicted "
                                 << ratios[0] << ", " << ratios[1] << ", " << ratios[2];
  }
}

// Each deliberately broken copy of the planned layout: exactly the sensors it breaks, each
// with exactly the reasons it should have.
TEST_F(PlanCliTest, CheckFlagsBrokenLayoutsWithTheRightReasons) {
  // The camera board moved out of the front camera's view.
  int exit_code = 0;
  const auto bad = CheckEdited(
      [](nlohmann::json& st) {
        Board(st, "front_camera_board")["pose"] = {{"xyz_m", {5.4, 5.0, 1.26}},
                                                   {"ypr_deg", {55, 0, 0}}};
      },
      kCornerNoise, &exit_code);
  EXPECT_EQ(exit_code, 1);
  // The surround front camera sees the board there, but too small.
  EXPECT_EQ(bad, (std::map<std::string, std::vector<std::string>>{
                     {"front_camera", {"board_outside_fov"}},
                     {"surround_front", {"features_too_small"}}}));
  // Shrunk boards: the camera board's squares and the bumper LiDAR boards' holes.
  EXPECT_EQ(
      CheckEdited([](nlohmann::json& st) { Board(st, "front_camera_board")["scale"] = 0.2; }),
      (std::map<std::string, std::vector<std::string>>{
          {"front_camera", {"features_too_small"}}, {"surround_front", {"features_too_small"}}}));
  EXPECT_EQ(CheckEdited([](nlohmann::json& st) {
              Board(st, "bumper_lidar_board_left")["scale"] = 0.5;
              Board(st, "bumper_lidar_board_right")["scale"] = 0.5;
            }),
            (std::map<std::string, std::vector<std::string>>{{"bumper_lidar", {"too_few_rings"}}}));
  // A stray board in front of the camera board and the roof LiDAR's left board; a board
  // moved into the aligner's zone.
  EXPECT_EQ(
      CheckEdited([](nlohmann::json& st) {
        st["boards"].push_back({{"id", "stray"},
                                {"type", "aruco"},
                                {"pose", {{"xyz_m", {4.3, 0.7, 1.3}}, {"ypr_deg", {0, 0, 0}}}}});
      }),
      (std::map<std::string, std::vector<std::string>>{{"front_camera", {"occluded_by_board"}},
                                                       {"surround_front", {"occluded_by_board"}},
                                                       {"roof_lidar", {"occluded_by_board"}}}));
  EXPECT_EQ(CheckEdited([](nlohmann::json& st) {
              nlohmann::json& pose = Board(st, "surround_left_board")["pose"];
              pose.erase("matrix");  // the matrix wins over xyz_m when reading
              pose["xyz_m"][1] = 1.6;
            }),
            (std::map<std::string, std::vector<std::string>>{{"surround_left", {"in_keep_out"}}}));
  // The same layout with corners 2 px noisy instead of 0.04 px.
  const auto noisy = CheckEdited([](nlohmann::json&) {}, " --corner-noise-px 2");
  ASSERT_TRUE(noisy.count("front_camera"));
  for (const auto& [name, reasons] : noisy) {
    EXPECT_EQ(reasons, std::vector<std::string>{"uncertainty_above_tolerance"}) << name;
  }
}

TEST(PlanCli, ValidRegionsContainThePlannedPose) {
  const fs::path dir =
      fs::path(testing::TempDir()) / ("plan_regions_" + std::to_string(::getpid()));
  const LinecalRun plan =
      RunLinecal("plan --json --car " + kCar + " --floor " + kFloor + " --out " + dir.string());
  ASSERT_EQ(plan.exit_code, 0) << plan.err;
  const nlohmann::json j = nlohmann::json::parse(plan.out);
  std::set<std::pair<std::string, std::string>> pairs;
  for (const nlohmann::json& r : j["valid_regions"]) {
    pairs.insert({r["sensor"].get<std::string>(), r["target"].get<std::string>()});
    SCOPED_TRACE(r["sensor"].get<std::string>() + " " + r["target"].get<std::string>());
    EXPECT_LE(r["distance_m"][0].get<double>(), r["distance_m"][1].get<double>());
    EXPECT_LE(r["lateral_m"][0].get<double>(), 0.0);
    EXPECT_GE(r["lateral_m"][1].get<double>(), 0.0);
    EXPECT_LE(r["heading_deg"][0].get<double>(), 0.0);
    EXPECT_GE(r["heading_deg"][1].get<double>(), 0.0);
    EXPECT_GE(r["polygon_m"].size(), 3u);
  }
  for (const nlohmann::json& s : j["sensors"]) {
    for (const nlohmann::json& t : s["targets"]) {
      EXPECT_TRUE(pairs.count({s["name"].get<std::string>(), t["id"].get<std::string>()}))
          << t["id"];
    }
  }
  // The distance range agrees with `plan check`: the front camera's board moved along the
  // camera's line of sight to just inside and just beyond its ends.
  nlohmann::json region;
  for (const nlohmann::json& r : j["valid_regions"]) {
    if (r["sensor"] == "front_camera" && r["target"] == "front_camera_board") region = r;
  }
  ASSERT_FALSE(region.is_null());
  nlohmann::json station = ReadJson(dir / "station.json");
  nlohmann::json* board = nullptr;
  for (nlohmann::json& b : station["boards"]) {
    if (b["id"] == "front_camera_board") board = &b;
  }
  ASSERT_NE(board, nullptr);
  board->at("pose").erase("matrix");
  const std::vector<double> xyz = board->at("pose")["xyz_m"];
  const double camera_x = 1.90;  // deploy/cars/reference.json; the board is straight ahead
  ASSERT_NEAR(xyz[1], 0.0, 1e-9);
  const auto front_camera_ok = [&](double distance) {
    board->at("pose")["xyz_m"] = {camera_x + distance, xyz[1], xyz[2]};
    const fs::path path = dir / "moved.json";
    WriteJson(path, station);
    const LinecalRun run = RunLinecal("plan check --json --station " + path.string() + " --car " +
                                      (dir / "car.json").string() + " --floor " + kFloor);
    const nlohmann::json result = nlohmann::json::parse(run.out);
    for (const nlohmann::json& s : result["sensors"]) {
      if (s["name"] != "front_camera") continue;
      if (!s["calibratable"].get<bool>())
        std::fprintf(stderr, "at %.2f m: %s\n", distance, s["reasons"].dump().c_str());
      return s["calibratable"].get<bool>();
    }
    return false;
  };
  const double lo = region["distance_m"][0], hi = region["distance_m"][1];
  EXPECT_TRUE(front_camera_ok(lo + 0.05));
  EXPECT_TRUE(front_camera_ok(hi - 0.05));
  EXPECT_FALSE(front_camera_ok(lo - 0.3));
  EXPECT_FALSE(front_camera_ok(hi + 0.3));
  fs::remove_all(dir);
}

// `plan check` on the reference layout names every partly hidden page (none hides a feature,
// and the detectors find those boards from what shows: tools_cmd_calibrate_targets_test);
// with front_vertical moved 0.2 m towards the car's axis it hides bumper_lidar_right's markers
// and holes from the three sensors that use that board, naming the board, the sensor, the
// occluder and the share hidden. (--min-feature-px 1: the reference's camera boards are
// below the 15 px design rule, docs/planner.md; that is not what is tested here.)
TEST(PlanCli, CheckNamesBoardsHiddenBehindOthers) {
  const fs::path dir = fs::path(testing::TempDir()) / ("plan_hidden_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  const fs::path reference = fs::path(LINECAL_SOURCE_DIR) / "deploy/stations/reference.json";
  // sensor/target -> (reasons, hidden_share, hidden_by) of every target with something hidden.
  struct Hidden {
    std::vector<std::string> reasons;
    double share = 0;
    std::string by;
  };
  const auto check = [&](const fs::path& station, int expected_exit) {
    const LinecalRun run = RunLinecal("plan check --json --min-feature-px 1 --station " +
                                      station.string() + " --car " + kCar);
    EXPECT_EQ(run.exit_code, expected_exit) << run.out << run.err;
    std::map<std::string, Hidden> out;
    const nlohmann::json result = nlohmann::json::parse(run.out);
    for (const nlohmann::json& s : result.at("sensors")) {
      if (s.at("kind") == "radar") continue;  // reflectors, no page
      for (const nlohmann::json& t : s.at("targets")) {
        if (t.at("hidden_by").is_null() && t.at("reasons").empty()) continue;
        out[s.at("name").get<std::string>() + "/" + t.at("id").get<std::string>()] = {
            t.at("reasons").get<std::vector<std::string>>(), t.at("hidden_share").get<double>(),
            t.at("hidden_by").get<std::string>()};
      }
    }
    return out;
  };
  // Shares in 24 x 24 page samples (station/planner/planner.cc, HiddenPageOf), of the samples
  // in the camera image (all for the LiDAR).
  const std::map<std::string, Hidden> as_built = check(reference, 0);
  ASSERT_EQ(as_built.size(), 3u);
  const Hidden& right = as_built.at("front_camera/bumper_lidar_right");
  EXPECT_EQ(right.reasons, std::vector<std::string>{});
  EXPECT_NEAR(right.share, 65.0 / 576, 1e-12);
  EXPECT_EQ(right.by, "front_vertical");
  const Hidden& far_left = as_built.at("front_camera/front_round_hole_left");
  EXPECT_EQ(far_left.reasons, std::vector<std::string>{});
  EXPECT_NEAR(far_left.share, 21.0 / 576, 1e-12);
  EXPECT_EQ(far_left.by, "front_circle");
  const Hidden& roof = as_built.at("roof_lidar/roof_lidar_left");
  EXPECT_EQ(roof.reasons, std::vector<std::string>{});
  EXPECT_NEAR(roof.share, 10.0 / 576, 1e-12);
  EXPECT_EQ(roof.by, "bumper_lidar_left");

  nlohmann::json station = ReadJson(reference);
  for (nlohmann::json& b : station.at("boards")) {
    if (b.at("id") == "front_vertical") b.at("pose").at("xyz_m") = {6.0, -2.0, 0.9};
  }
  const fs::path moved = dir / "front_vertical_moved.json";
  WriteJson(moved, station);
  const std::map<std::string, Hidden> hidden = check(moved, 1);
  ASSERT_EQ(hidden.size(), 5u);
  const std::vector<std::string> occluded = {"occluded_by_board"};
  for (const auto& [key, share] :
       std::map<std::string, double>{{"front_camera/bumper_lidar_right", 154.0 / 576},
                                     {"surround_front/bumper_lidar_right", 63.0 / 576},
                                     {"bumper_lidar/bumper_lidar_right", 60.0 / 576}}) {
    SCOPED_TRACE(key);
    ASSERT_EQ(hidden.count(key), 1u);
    EXPECT_EQ(hidden.at(key).reasons, occluded);
    EXPECT_NEAR(hidden.at(key).share, share, 1e-12);
    EXPECT_EQ(hidden.at(key).by, "front_vertical");
  }
  // The text names them too.
  const LinecalRun text =
      RunLinecal("plan check --min-feature-px 1 --station " + moved.string() + " --car " + kCar);
  EXPECT_NE(
      text.out.find(
          "bumper_lidar_right: occluded_by_board hidden behind 'front_vertical'; 27% of the page "
          "hidden, most behind 'front_vertical';"),
      std::string::npos)
      << text.out;
  fs::remove_all(dir);
}

TEST(PlanCli, BadInputExitsTwoNamingTheProblem) {
  const fs::path dir = fs::path(testing::TempDir()) / ("plan_bad_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const auto expect_bad = [&](const std::string& args, const std::string& named) {
    const LinecalRun run = RunLinecal(args);
    EXPECT_EQ(run.exit_code, 2) << args << "\n" << run.out;
    EXPECT_NE(run.err.find(named), std::string::npos) << args << "\n" << run.err;
  };
  expect_bad("plan --floor " + kFloor + " --out " + dir.string(), "--car");
  expect_bad("plan --car /nonexistent/car.json --floor " + kFloor + " --out " + dir.string(),
             "/nonexistent/car.json");
  const fs::path floor = dir / "floor.json";
  std::ofstream(floor)
      << R"({"format": "linecal.floor", "version": 1, "name": "x", "usable_area_m": [[0, 0], [1, 0]]})";
  expect_bad("plan --car " + kCar + " --floor " + floor.string() + " --out " + dir.string(),
             floor.string() + ": usable_area_m");
  expect_bad("plan --car " + kCar + " --floor " + kFloor + " --out " + dir.string() +
                 " --min-feature-px -3",
             "--min-feature-px");
  const fs::path station = dir / "station.json";
  std::ofstream(station) << R"({"format": "linecal.station", "version": 1, "name": "x",
      "boards": [{"id": "b", "type": "chess", "pose": {"xyz_m": [1, 0, 1], "ypr_deg": [0, 0, 0]}}]})";
  expect_bad("plan check --station " + station.string() + " --car " + kCar,
             station.string() + ": boards[0].type");
  expect_bad("plan check --station " + station.string(), "--car");
  fs::remove_all(dir);
}

}  // namespace
}  // namespace linecal
