// `linecal radar decode` run as a program: output, summary and exit codes (docs/interfaces.md).
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <numbers>
#include <sstream>

#include "station/io/candump.h"
#include "station/sensors/radar/radar_format.h"
#include "tests/support/scoped_path.h"
#include "tests/tools/run_linecal.h"

namespace linecal {
namespace {

using testing_tools::LinecalRun;
using testing_tools::RunLinecal;

std::string WriteLog(const std::string& name, const std::string& text) {
  const std::filesystem::path path = std::filesystem::path(testing::TempDir()) / name;
  std::ofstream(path) << text;
  return path.string();
}

std::vector<nlohmann::json> JsonLines(const std::string& out) {
  std::vector<nlohmann::json> lines;
  std::istringstream in(out);
  std::string line;
  while (std::getline(in, line)) lines.push_back(nlohmann::json::parse(line));
  return lines;
}

// A status frame announcing one cluster, docs/sensors.md's worked example, a remote frame and an
// unknown id.
constexpr char kArsLog[] =
    "(1600000000.000000) can0 600#0100000710\n"
    "(1600000000.000250) can0 701#0564FE8E800160A4\n"
    "(1600000000.000500) can0 701#R\n"
    "(1600000000.000750) can0 201#0000000000000000\n";

TEST(CmdRadarTest, Ars408JsonLinesCarryTheWorkedExample) {
  const LinecalRun run =
      RunLinecal("radar decode --model ars408 --json --log " + WriteLog("ars.log", kArsLog));
  ASSERT_EQ(run.exit_code, 0) << run.err;
  const std::vector<nlohmann::json> lines = JsonLines(run.out);
  ASSERT_EQ(lines.size(), 1u) << run.out;
  const nlohmann::json& j = lines[0];
  constexpr double kPrintedDigits = 0.005;  // docs/sensors.md rounds to two decimals
  EXPECT_EQ(j["t_ns"].get<int64_t>(), 1600000000LL * 1000000000LL);
  EXPECT_EQ(j["id"], 5);
  EXPECT_EQ(j["kind"], "cluster");
  EXPECT_EQ(j["sensor_id"], 0);
  EXPECT_EQ(j["cycle"], 7);
  EXPECT_NEAR(j["range_m"].get<double>(), 148.95, kPrintedDigits);
  EXPECT_NEAR(j["azimuth_deg"].get<double>(), 11.03, kPrintedDigits);
  EXPECT_NEAR(j["rcs_dbsm"].get<double>(), 18.0, 1e-9);
  EXPECT_TRUE(j.contains("range_rate_mps"));
  EXPECT_NE(run.err.find("4 frames read, 2 decoded, 2 skipped (unknown_id 1, remote 1); "
                         "1 cycles (0 incomplete), 1 detections"),
            std::string::npos)
      << run.err;
}

TEST(CmdRadarTest, TableWithoutJson) {
  const LinecalRun run =
      RunLinecal("radar decode --model ars408 --log " + WriteLog("ars_t.log", kArsLog));
  ASSERT_EQ(run.exit_code, 0) << run.err;
  EXPECT_EQ(run.out.rfind("t_ns", 0), 0u) << run.out;
  EXPECT_NE(run.out.find("cluster"), std::string::npos) << run.out;
  EXPECT_NE(run.out.find("148.95"), std::string::npos) << run.out;
  EXPECT_NE(run.out.find("11.03"), std::string::npos) << run.out;
}

TEST(CmdRadarTest, EsrTracksHaveNoRcs) {
  RadarCycle scan;
  scan.kind = RadarDetectionKind::kTrack;
  scan.time = CanTime(std::chrono::seconds(1700000000));
  scan.counter = 42;
  RadarDetection d;
  d.kind = RadarDetectionKind::kTrack;
  d.id = 3;
  d.range_m = 25.0;
  d.azimuth_rad = -5.0 * std::numbers::pi / 180.0;  // 5° to the right
  d.range_rate_mps = -1.5;
  scan.detections.push_back(d);
  const testing_support::ScopedPath scratch("cmd_esr", ".log");
  const std::string path = scratch.string();
  ASSERT_TRUE(WriteCandumpLog(path, *EncodeEsrScan(scan, "can0", {})).ok());
  const LinecalRun run = RunLinecal("radar decode --model esr --json --log " + path);
  ASSERT_EQ(run.exit_code, 0) << run.err;
  const std::vector<nlohmann::json> lines = JsonLines(run.out);
  ASSERT_EQ(lines.size(), 1u);
  EXPECT_EQ(lines[0]["id"], 3);
  EXPECT_EQ(lines[0]["kind"], "track");
  EXPECT_EQ(lines[0]["cycle"], 42);
  EXPECT_NEAR(lines[0]["range_m"].get<double>(), 25.0, 0.05);      // 0.1 m steps
  EXPECT_NEAR(lines[0]["azimuth_deg"].get<double>(), -5.0, 0.05);  // 0.1° steps
  EXPECT_NEAR(lines[0]["range_rate_mps"].get<double>(), -1.5, 0.005);
  EXPECT_FALSE(lines[0].contains("rcs_dbsm"));
  // The other angle convention mirrors the azimuth.
  const LinecalRun ccw =
      RunLinecal("radar decode --model esr --json --esr-angle counterclockwise --log " + path);
  ASSERT_EQ(ccw.exit_code, 0) << ccw.err;
  EXPECT_NEAR(JsonLines(ccw.out).at(0)["azimuth_deg"].get<double>(), 5.0, 0.05);
}

TEST(CmdRadarTest, NoDetectionsIsANegativeAnswer) {
  // An ESR log decoded as ARS408: every frame is an unknown id.
  const LinecalRun run =
      RunLinecal("radar decode --model ars408 --log " +
                 WriteLog("esr_as_ars.log", "(1.0) can0 4E0#0000000000000000\n"));
  EXPECT_EQ(run.exit_code, 1) << run.err;
  EXPECT_NE(run.err.find("unknown_id 1"), std::string::npos) << run.err;
}

TEST(CmdRadarTest, BadInputExitsTwoWithAOneLineMessage) {
  const std::string log = WriteLog("ok.log", kArsLog);
  struct Case {
    std::string args;
    std::string message_part;
  };
  const Case cases[] = {
      {"--model ars408 --log /nonexistent/radar.log", "/nonexistent/radar.log: cannot open"},
      {"--model srr --log " + log, "--model: unknown model 'srr'"},
      {"--log " + log, "missing --model"},
      {"--model esr", "missing --log"},
      {"--model ars408 --ars408-counter middle --log " + log, "--ars408-counter: 'middle'"},
      {"--model ars408 --log " + WriteLog("bad.log", "(1.0) can0 701#0564\n(2.0) can0 7G1#00\n"),
       "bad.log:2: bad CAN id '7G1'"},
  };
  for (const Case& c : cases) {
    const LinecalRun run = RunLinecal("radar decode " + c.args);
    EXPECT_EQ(run.exit_code, 2) << c.args << "\n" << run.err;
    EXPECT_NE(run.err.find(c.message_part), std::string::npos) << c.args << "\n" << run.err;
    EXPECT_EQ(std::count(run.err.begin(), run.err.end(), '\n'), 1) << run.err;
  }
}

TEST(CmdRadarTest, HelpExitsZero) {
  const LinecalRun run = RunLinecal("radar decode --help");
  EXPECT_EQ(run.exit_code, 0);
  EXPECT_NE(run.out.find("--model ars408|esr"), std::string::npos) << run.out;
}

}  // namespace
}  // namespace linecal
