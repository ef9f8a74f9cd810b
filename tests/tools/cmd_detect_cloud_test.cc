// `linecal detect --board round_hole --cloud ...` run as a program (docs/interfaces.md): simulated
// scans written as PCD files (binary, binary_compressed, and ascii without a ring field), the
// JSON object checked against the truth, the exit codes (0 found, 1 not found, 2 bad usage or
// input) and the real reference scans of docs/external-data.md, which hold no board.
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

#include "station/sensors/lidar/pcd.h"
#include "tests/detectors/round_hole/round_hole_scene.h"
#include "tests/support/external_data.h"
#include "tests/tools/run_linecal.h"

namespace linecal {
namespace {

using testing_tools::RunLinecal;

class DetectCloudCliTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::filesystem::temp_directory_path() /
           ("linecal_detect_cloud_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }
  std::string Path(const std::string& name) const { return (dir_ / name).string(); }

  // Writes the scene's frames as PCD files and returns the --cloud arguments.
  std::string WriteFrames(const Scene& scene, PcdEncoding encoding) {
    std::string args;
    for (std::size_t f = 0; f < scene.frames.size(); ++f) {
      std::vector<LidarPoint> points;
      for (const RoundHoleCloudPoint& p : scene.frames[f])
        points.push_back({p.x, p.y, p.z, 100.0f, p.ring, 0});
      const std::string path = Path("scan-" + std::to_string(f) + ".pcd");
      EXPECT_TRUE(WritePcd(path, points, encoding).ok());
      args += " --cloud " + path;
    }
    return args;
  }

  // The JSON report checked against the truth: every hole within bar_m, the board frame's
  // positions of the features, T_lidar_board's translation and normal.
  void ExpectBoard(const nlohmann::json& j, const Scene& scene, double bar_m) {
    EXPECT_EQ(j.at("board"), "round_hole");
    EXPECT_EQ(j.at("found"), true);
    EXPECT_EQ(j.at("reason"), "");
    EXPECT_GT(j.at("elapsed_ms").get<double>(), 0.0);
    ASSERT_EQ(j.at("features").size(), 5u);
    for (const nlohmann::json& f : j.at("features")) {
      const int id = f.at("id");
      const Eigen::Vector2d p_board = scene.board.features().at(id).p_board;
      EXPECT_EQ(scene.board.features().at(id).kind, FeatureKind::kHoleCentre);
      EXPECT_NEAR(f.at("x").get<double>(), p_board.x(), 1e-12);
      EXPECT_NEAR(f.at("y").get<double>(), p_board.y(), 1e-12);
      const Eigen::Vector3d truth =
          scene.T_lidar_board * Eigen::Vector3d(p_board.x(), p_board.y(), 0);
      const Eigen::Vector3d p(f.at("p")[0].get<double>(), f.at("p")[1].get<double>(),
                              f.at("p")[2].get<double>());
      EXPECT_LT((p - truth).norm(), bar_m) << "hole " << id;
    }
    const nlohmann::json& T = j.at("T_lidar_board");
    ASSERT_EQ(T.size(), 16u);
    const Eigen::Matrix4d truth = scene.T_lidar_board.Matrix();
    for (int r = 0; r < 3; ++r) {
      EXPECT_NEAR(T[4 * r + 3].get<double>(), truth(r, 3), bar_m) << "translation " << r;
      // The normal (third column) within 0.5 degree.
      EXPECT_NEAR(T[4 * r + 2].get<double>(), truth(r, 2), 0.009) << "normal " << r;
    }
    EXPECT_EQ(T[12], 0.0);
    EXPECT_EQ(T[15], 1.0);
    // One board passed: ranked alone, chosen, its centre the board's.
    const nlohmann::json& boards = j.at("boards");
    ASSERT_EQ(boards.size(), 1u);
    EXPECT_EQ(boards[0].at("verdict"), "chosen");
    EXPECT_EQ(boards[0].at("rms_ratio"), 1.0);
    EXPECT_GT(boards[0].at("edges").get<int>(), 0);
    EXPECT_LE(boards[0].at("hole_fill").get<double>(), 0.15);
    for (int r = 0; r < 3; ++r) {
      EXPECT_NEAR(boards[0].at("centre")[r].get<double>(), truth(r, 3), bar_m) << "centre " << r;
    }
  }

  std::filesystem::path dir_;
};

TEST_F(DetectCloudCliTest, FindsTheBoardInAccumulatedClouds) {
  // Pandar64 at 5 m (bar 1 cm), binary_compressed; VLP-16 at 7 m (bar 2 cm), binary.
  const Scene p64 = Simulate(Beams("roof_lidar"), 5.0, 35.0, -20.0, 0.02, 10);
  auto run = RunLinecal("detect --board round_hole" +
                        WriteFrames(p64, PcdEncoding::kBinaryCompressed) + " --json");
  ASSERT_EQ(run.exit_code, 0) << run.err << run.out;
  nlohmann::json j = nlohmann::json::parse(run.out);
  ExpectBoard(j, p64, 0.01);
  EXPECT_EQ(j.at("clouds"), 10);
  EXPECT_EQ(j.at("rings_from_elevation"), false);

  const Scene vlp = Simulate(Beams("bumper_lidar"), 7.0, -50.0, 15.0, 0.02, 10);
  run =
      RunLinecal("detect --board round_hole" + WriteFrames(vlp, PcdEncoding::kBinary) + " --json");
  ASSERT_EQ(run.exit_code, 0) << run.err << run.out;
  ExpectBoard(nlohmann::json::parse(run.out), vlp, 0.02);

  // The table form: found, and one line per hole.
  run = RunLinecal("detect --board round_hole" + WriteFrames(vlp, PcdEncoding::kBinary));
  EXPECT_EQ(run.exit_code, 0) << run.err;
  EXPECT_NE(run.out.find("round_hole: found"), std::string::npos) << run.out;
}

TEST_F(DetectCloudCliTest, AsciiCloudWithoutRings) {
  const Scene scene = Simulate(Beams("bumper_lidar"), 4.0, 10.0, 30.0, 0.02, 5);
  std::string args;
  for (std::size_t f = 0; f < scene.frames.size(); ++f) {
    const std::string path = Path("xyz-" + std::to_string(f) + ".pcd");
    std::ofstream out(path);
    out << "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH "
        << scene.frames[f].size() << "\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS "
        << scene.frames[f].size() << "\nDATA ascii\n";
    out.precision(9);
    for (const RoundHoleCloudPoint& p : scene.frames[f])
      out << p.x << ' ' << p.y << ' ' << p.z << '\n';
    args += " --cloud " + path;
  }
  const auto run = RunLinecal("detect --board round_hole" + args + " --json");
  ASSERT_EQ(run.exit_code, 0) << run.err << run.out;
  const nlohmann::json j = nlohmann::json::parse(run.out);
  EXPECT_EQ(j.at("rings_from_elevation"), true);
  ExpectBoard(j, scene, 0.02);
}

TEST_F(DetectCloudCliTest, NotFoundAndBadInput) {
  // An empty cloud: not found, with a reason, exit 1.
  ASSERT_TRUE(WritePcd(Path("empty.pcd"), {}, PcdEncoding::kAscii).ok());
  auto run = RunLinecal("detect --board round_hole --cloud " + Path("empty.pcd") + " --json");
  EXPECT_EQ(run.exit_code, 1) << run.err;
  nlohmann::json j = nlohmann::json::parse(run.out);
  EXPECT_EQ(j.at("found"), false);
  EXPECT_EQ(j.at("reason"), "no_points");
  EXPECT_TRUE(j.at("features").empty());
  EXPECT_TRUE(j.at("T_lidar_board").is_null());

  // A missing file, and a corrupt one, are named; exit 2.
  run = RunLinecal("detect --board round_hole --cloud " + Path("empty.pcd") + " --cloud " +
                   Path("missing.pcd"));
  EXPECT_EQ(run.exit_code, 2);
  EXPECT_NE(run.err.find("missing.pcd"), std::string::npos) << run.err;
  {
    std::ofstream bad(Path("corrupt.pcd"));
    bad << "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 1000\nHEIGHT "
           "1\nPOINTS 1000\nDATA binary\nshort";
  }
  run = RunLinecal("detect --board round_hole --cloud " + Path("corrupt.pcd"));
  EXPECT_EQ(run.exit_code, 2);
  EXPECT_NE(run.err.find("corrupt.pcd"), std::string::npos) << run.err;

  // --cloud with another board, with --image, with --overlay.
  run = RunLinecal("detect --board aruco --cloud " + Path("empty.pcd"));
  EXPECT_EQ(run.exit_code, 2);
  EXPECT_NE(run.err.find("--board aruco"), std::string::npos) << run.err;
  run = RunLinecal("detect --board round_hole --cloud " + Path("empty.pcd") + " --image x.png");
  EXPECT_EQ(run.exit_code, 2);
  run = RunLinecal("detect --board round_hole --cloud " + Path("empty.pcd") + " --overlay o.png");
  EXPECT_EQ(run.exit_code, 2);
  run = RunLinecal("detect --board round_hole");
  EXPECT_EQ(run.exit_code, 2);
  EXPECT_NE(run.err.find("--cloud"), std::string::npos) << run.err;
}

// The real scans (a VLP-16 and a Pandar64 decoded by nebula; no board in them, and no ring
// field: nebula calls it "channel"): not found, exit 1, never a false board.
TEST_F(DetectCloudCliTest, RealScansHoldNoBoard) {
  for (const char* model : {"vlp16", "pandar64"}) {
    LINECAL_EXTERNAL_OR_SKIP(path, std::string("lidar/") + model + "/reference_scan.pcd");
    const auto run = RunLinecal("detect --board round_hole --cloud " + path + " --json");
    EXPECT_EQ(run.exit_code, 1) << model << ": " << run.err << run.out;
    const nlohmann::json j = nlohmann::json::parse(run.out);
    EXPECT_EQ(j.at("found"), false) << model;
    EXPECT_NE(j.at("reason"), "") << model;
    EXPECT_TRUE(j.at("features").empty()) << model;
    EXPECT_EQ(j.at("rings_from_elevation"), true) << model;
  }
}

}  // namespace
}  // namespace linecal
