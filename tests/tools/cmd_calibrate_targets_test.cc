// Issue 20's bar "every planned target found in every frame of the reference station, for
// every sensor", for the cameras, through the built binary with the detectors in the loop: the
// reference car's cameras are rendered by `linecal sim` in the reference station and
// calibrated by `linecal calibrate`; every board a camera's car model names as a target must
// be found whole in every frame. (bumper_lidar_right, partly behind front_vertical in the front
// camera's view, was refused as `ambiguous` before: docs/station-and-car.md.) Two frames a
// camera with sensor noise and blur, so that the frames differ. Seeds 1-3 only, for the CI
// budget (about 23 s of CPU); seeds 1-10 with three such frames were checked by hand
// (docs/detectors.md, "Boards partly hidden by another").
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "tests/tools/json_file.h"
#include "tests/tools/run_linecal.h"

namespace linecal {
namespace {

namespace fs = std::filesystem;
using testing_tools::ReadJson;
using testing_tools::RunLinecal;

TEST(CalibrateTargetsTest, EveryCameraFindsEveryPlannedBoardInEveryFrame) {
  constexpr int kFrames = 2;
  const fs::path deploy = fs::path(LINECAL_SOURCE_DIR) / "deploy";
  const nlohmann::json car = ReadJson(deploy / "cars/reference.json");
  // The cameras and the boards each plans to use, from the car model.
  std::map<std::string, std::vector<std::string>> targets;
  std::string cameras;
  for (const nlohmann::json& s : car.at("sensors")) {
    if (s.at("kind") != "camera") continue;
    const std::string name = s.at("name");
    targets[name] = s.at("targets").get<std::vector<std::string>>();
    if (!cameras.empty()) cameras += ',';
    cameras += name;
  }
  ASSERT_EQ(targets.size(), 5u);
  const fs::path dir =
      fs::path(testing::TempDir()) / ("calibrate_targets_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  for (int seed : {1, 2, 3}) {
    SCOPED_TRACE("seed " + std::to_string(seed));
    const fs::path capture = dir / ("capture_" + std::to_string(seed));
    const auto sim =
        RunLinecal("sim --station " + (deploy / "stations/reference.json").string() + " --car " +
                   (deploy / "cars/reference.json").string() + " --seed " + std::to_string(seed) +
                   " --sensors " + cameras + " --frames " + std::to_string(kFrames) +
                   " --noise 2 --blur 0.5 --out " + capture.string());
    ASSERT_EQ(sim.exit_code, 0) << sim.err;
    std::map<std::string, int> frames;
    // Named: a range-for over ReadJson(...).at(...) would walk a destroyed temporary.
    const nlohmann::json manifest = ReadJson(capture / "manifest.json");
    for (const nlohmann::json& s : manifest.at("sensors")) {
      frames[s.at("name").get<std::string>()] = static_cast<int>(s.at("frames").size());
    }
    const auto run = RunLinecal("calibrate --json --capture " + capture.string());
    ASSERT_EQ(run.exit_code, 0) << run.out << run.err;
    const nlohmann::json result = nlohmann::json::parse(run.out);
    ASSERT_EQ(result.at("sensors").size(), targets.size());
    for (const nlohmann::json& s : result.at("sensors")) {
      const std::string name = s.at("name");
      SCOPED_TRACE(name);
      ASSERT_EQ(frames[name], kFrames);
      EXPECT_EQ(s.at("verdict"), "pass");
      std::vector<std::string> reported;
      for (const nlohmann::json& b : s.at("boards")) {
        reported.push_back(b.at("board"));
        EXPECT_EQ(b.at("frames_found").get<int>(), frames[name])
            << b.at("board") << ": " << b.at("frames_partial") << " partial, reason "
            << b.at("reason");
        EXPECT_EQ(b.at("frames_partial").get<int>(), 0) << b.at("board");
      }
      EXPECT_EQ(reported, targets[name]);
    }
  }
  fs::remove_all(dir);
}

}  // namespace
}  // namespace linecal
