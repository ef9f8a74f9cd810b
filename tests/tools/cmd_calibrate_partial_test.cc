// Issue 19, "Partial views": the station's targets require the whole board unless the station
// file allows a partial view of it (`allow_partial`, docs/station-and-car.md). Through the
// built binary: `linecal sim` renders the reference car's front camera with a ChArUco board
// added at the right edge of its view, so that only part of the board is in the image; the
// capture is calibrated once as rendered (the board allows partial views) and once with
// `allow_partial` taken out of the capture's station file.
#include <gtest/gtest.h>
#include <unistd.h>

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

void WriteJson(const fs::path& path, const nlohmann::json& j) { std::ofstream(path) << j.dump(2); }

// The reference station with a 9 x 6 ChArUco board at the right edge of the front camera's
// view (about half of it in the image), and the reference car cut down to the front camera
// with that board as its third target.
void WriteStationAndCar(const fs::path& dir) {
  const fs::path deploy = fs::path(LINECAL_SOURCE_DIR) / "deploy";
  nlohmann::json station = ReadJson(deploy / "stations/reference.json");
  station.at("boards").push_back(
      {{"id", "edge_charuco"},
       {"type", "charuco"},
       {"cols", 9},
       {"rows", 6},
       {"square_m", 0.08},
       {"marker_m", 0.06},
       {"allow_partial", true},
       {"pose", {{"xyz_m", {6.0, -2.6, 1.2}}, {"ypr_deg", {-20, 0, 0}}}}});
  WriteJson(dir / "station.json", station);
  nlohmann::json car = ReadJson(deploy / "cars/reference.json");
  nlohmann::json front;
  for (const nlohmann::json& s : car.at("sensors")) {
    if (s.at("name") == "front_camera") front = s;
  }
  front["targets"] = {"front_chessboard", "front_circle", "edge_charuco"};
  car["sensors"] = nlohmann::json::array({front});
  WriteJson(dir / "car.json", car);
}

// `linecal calibrate --json` of the capture: the front camera's result.
nlohmann::json CalibrateFrontCamera(const fs::path& capture) {
  const auto run = RunLinecal("calibrate --json --capture " + capture.string());
  EXPECT_EQ(run.exit_code, 0) << run.out << run.err;
  const nlohmann::json result = nlohmann::json::parse(run.out);
  EXPECT_EQ(result.at("sensors").size(), 1u);
  return result.at("sensors").at(0);
}

nlohmann::json BoardSummary(const nlohmann::json& sensor, const std::string& board) {
  for (const nlohmann::json& b : sensor.at("boards")) {
    if (b.at("board") == board) return b;
  }
  ADD_FAILURE() << "no board " << board;
  return {};
}

TEST(CalibratePartialTest, PartialViewUsedOnlyWhereTheStationAllowsIt) {
  const fs::path dir =
      fs::path(testing::TempDir()) / ("calibrate_partial_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  WriteStationAndCar(dir);
  const fs::path capture = dir / "capture";
  const auto sim = RunLinecal("sim --station " + (dir / "station.json").string() + " --car " +
                              (dir / "car.json").string() + " --seed 2 --out " + capture.string());
  ASSERT_EQ(sim.exit_code, 0) << sim.err;

  const nlohmann::json allowed = CalibrateFrontCamera(capture);
  const nlohmann::json allowed_board = BoardSummary(allowed, "edge_charuco");
  EXPECT_EQ(allowed.at("verdict"), "pass");
  EXPECT_EQ(allowed_board.at("frames_found"), 0);
  EXPECT_EQ(allowed_board.at("frames_partial"), 1);
  EXPECT_EQ(allowed_board.at("partial_allowed"), true);
  EXPECT_EQ(allowed_board.at("reason"), "");

  // The same frame with the station's default: the partial view is counted, named and unused.
  nlohmann::json station = ReadJson(capture / "station.json");
  for (nlohmann::json& b : station.at("boards")) b.erase("allow_partial");
  WriteJson(capture / "station.json", station);
  const nlohmann::json refused = CalibrateFrontCamera(capture);
  const nlohmann::json refused_board = BoardSummary(refused, "edge_charuco");
  EXPECT_EQ(refused.at("verdict"), "pass");
  EXPECT_EQ(refused_board.at("frames_found"), 0);
  EXPECT_EQ(refused_board.at("frames_partial"), 1);
  EXPECT_EQ(refused_board.at("partial_allowed"), false);
  EXPECT_EQ(refused_board.at("reason"), "partial");

  // Without the board among the targets the camera uses exactly what it used when the partial
  // view was refused; with it allowed, at least the four corners a ChArUco partial view needs.
  nlohmann::json car = ReadJson(capture / "car.json");
  car.at("sensors").at(0)["targets"] = {"front_chessboard", "front_circle"};
  WriteJson(capture / "car.json", car);
  const nlohmann::json without = CalibrateFrontCamera(capture);
  EXPECT_EQ(refused.at("features_used"), without.at("features_used"));
  EXPECT_GE(allowed.at("features_used").get<int>(), without.at("features_used").get<int>() + 4);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace linecal
