// `linecal lidar decode` as a user runs it: the built binary, its files and exit codes.
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

#include "gtest/gtest.h"
#include "station/io/pcap.h"
#include "station/sensors/lidar/lidar_format.h"
#include "station/sensors/lidar/pcd.h"
#include "tests/support/external_data.h"
#include "tests/support/lidar_recording.h"
#include "tests/tools/run_linecal.h"

namespace linecal {
namespace {

using testing_tools::LinecalRun;
using testing_tools::RunLinecal;

class LidarDecodeCli : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::filesystem::temp_directory_path() /
           (std::string("lidar_decode_") +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    std::filesystem::remove_all(dir_);
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }
  // 5 turns of dual-return VLP-16 packets (150 a turn) from the project's encoder, as
  // dir_/vlp16.pcap.
  std::string EncodedVlp16() const {
    const std::filesystem::path path = dir_ / "vlp16.pcap";
    EXPECT_TRUE(
        testing_support::WriteRecordingPcap(
            testing_support::EncodeRecording(LidarModel::kVlp16, LidarReturnMode::kDual, 5.0), path)
            .ok());
    return path.string();
  }
  std::filesystem::path dir_;
};

// The real recordings (docs/external-data.md), decoded by the command.
TEST_F(LidarDecodeCli, Vlp16WritesOnePcdPerRotation) {
  LINECAL_EXTERNAL_OR_SKIP(pcap, "lidar/vlp16/packets.pcap");
  const LinecalRun r =
      RunLinecal("lidar decode --model vlp16 --pcap " + pcap + " --out " + (dir_ / "out").string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("packets read:        603"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("packets skipped:     0\n"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("scans written:       3"), std::string::npos) << r.out;
  for (int i = 0; i < 3; ++i) {
    char name[32];
    std::snprintf(name, sizeof(name), "scan-%06d.pcd", i);
    EXPECT_TRUE(std::filesystem::exists(dir_ / "out" / name)) << name;
  }
  EXPECT_FALSE(std::filesystem::exists(dir_ / "out" / "scan-000003.pcd"));
  // The third rotation holds nebula's reference scan plus 50 returns (see the decoder test).
  absl::StatusOr<PcdCloud> scan = ReadPcd(dir_ / "out" / "scan-000002.pcd");
  ASSERT_TRUE(scan.ok()) << scan.status();
  EXPECT_EQ(scan->points.size(), 14831u + 50u);
  EXPECT_TRUE(scan->has_ring && scan->has_time && scan->has_intensity);
}

TEST_F(LidarDecodeCli, Pandar64JsonSummary) {
  LINECAL_EXTERNAL_OR_SKIP(pcap, "lidar/pandar64/packets.pcap");
  LINECAL_EXTERNAL_OR_SKIP(angles, "lidar/pandar64/Pandar64.csv");
  const LinecalRun r = RunLinecal("lidar decode --model pandar64 --angles " + angles + " --pcap " +
                                  pcap + " --out " + dir_.string() + " --port 2368 --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["model"], "pandar64");
  EXPECT_EQ(j["packets_read"], 2400);
  EXPECT_EQ(j["packets_decoded"], 2400);
  EXPECT_EQ(j["packets_skipped"], 0);
  EXPECT_EQ(j["skipped"]["truncated"], 0);
  EXPECT_EQ(j["partial_rotations"], 3);
  EXPECT_EQ(j["scans_written"], 3);
  absl::StatusOr<PcdCloud> scan = ReadPcd(dir_ / "scan-000001.pcd");
  ASSERT_TRUE(scan.ok());
  EXPECT_EQ(scan->points.size(), 93591u);  // nebula's reference scan, point for point
}

// No real PandarXT-32 recording exists: write one with the encoder, with a few
// damaged packets, and decode it through the CLI.
TEST_F(LidarDecodeCli, PandarXt32FromAnEncodedRecording) {
  std::string csv = "Channel,Elevation,Azimuth\n";
  for (int c = 1; c <= 32; ++c) csv += std::to_string(c) + "," + std::to_string(16 - c) + ",0\n";
  std::ofstream(dir_ / "xt32.csv") << csv;
  LidarEncodeSettings s;
  s.model = LidarModel::kPandarXt32;
  s.first_column_time_ns = 1'700'000'000'000'000'000;
  // 3.5 turns at 0.18° per column from 0°: rotation 0 has no observed start, 1 and 2 are
  // complete, 3 has no end.
  std::vector<LidarColumn> cols(7000);
  for (int k = 0; k < 7000; ++k) {
    cols[k].azimuth_centideg = static_cast<std::uint16_t>(k * 18 % 36000);
    cols[k].echoes.assign(32, LidarEcho{8.0, 50});
  }
  const auto packets = EncodeLidarPackets(s, cols);
  ASSERT_TRUE(packets.ok()) << packets.status();
  absl::StatusOr<PcapWriter> w = PcapWriter::Create(dir_ / "xt32.pcap");
  ASSERT_TRUE(w.ok());
  for (std::size_t i = 0; i < packets->size(); ++i) {
    std::vector<std::uint8_t> p = (*packets)[i];
    if (i == 10) p.resize(500);  // truncated
    if (i == 20) p[0] = 0;       // wrong magic
    ASSERT_TRUE(w->WriteUdp(s.first_column_time_ns + i * 400'000, UdpEndpoints{}, p).ok());
  }
  ASSERT_TRUE(w->Close().ok());
  const LinecalRun r =
      RunLinecal("lidar decode --model pandarxt32 --angles " + (dir_ / "xt32.csv").string() +
                 " --pcap " + (dir_ / "xt32.pcap").string() + " --out " + (dir_ / "out").string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("packets skipped:     2 (truncated 1, bad_magic 1)"), std::string::npos)
      << r.out;
  EXPECT_NE(r.out.find("scans written:       2"), std::string::npos) << r.out;
  absl::StatusOr<PcdCloud> scan = ReadPcd(dir_ / "out" / "scan-000001.pcd");
  ASSERT_TRUE(scan.ok());
  // A full turn: 2000 columns of 32 beams (the damaged packets were in rotation 0).
  EXPECT_EQ(scan->points.size(), 2000u * 32u);
}

TEST_F(LidarDecodeCli, BadInputExitsWithTwoAndNamesTheProblem) {
  const std::string pcap = EncodedVlp16();
  const std::string pandar64_angles = (dir_ / "Pandar64.csv").string();
  std::ofstream(pandar64_angles) << testing_support::SyntheticAngleCsv(LidarModel::kPandar64);
  const std::string out = " --out " + dir_.string();
  struct Case {
    std::string args;
    std::string message;
  };
  std::ofstream(dir_ / "not.pcap") << "hello";
  const std::vector<Case> cases = {
      {"lidar decode --model vlp16 --pcap /nonexistent.pcap" + out, "/nonexistent.pcap"},
      {"lidar decode --model vlp32 --pcap " + pcap + out, "--model: unknown model 'vlp32'"},
      {"lidar decode --model pandar64 --pcap " + pcap + out, "--angles: pandar64"},
      {"lidar decode --model pandar64 --angles /nonexistent.csv --pcap " + pcap + out,
       "/nonexistent.csv"},
      {"lidar decode --model pandarxt32 --angles " + pandar64_angles + " --pcap " + pcap + out,
       "more than 32 channels"},
      {"lidar decode --model vlp16 --pcap " + (dir_ / "not.pcap").string() + out,
       "not.pcap: not a pcap file"},
      {"lidar decode --model vlp16 --pcap " + pcap, "missing --out"},
      {"lidar decode --model vlp16 --pcap " + pcap + out + " --port 70000", "--port: 70000"},
      {"lidar decode --model vlp16 --pcap " + pcap + out + " --min-range 5 --max-range 1",
       "max_range_m"},
      {"lidar decode --model vlp16 --pcap " + pcap + " --out /proc/forbidden", "--out"},
  };
  for (const Case& c : cases) {
    const LinecalRun r = RunLinecal(c.args);
    EXPECT_EQ(r.exit_code, 2) << c.args << "\n" << r.err;
    EXPECT_NE(r.err.find(c.message), std::string::npos) << r.err << " should name " << c.message;
    // One line.
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
  }
}

TEST_F(LidarDecodeCli, NoFullRotationExitsWithOne) {
  // The first 100 packets of a VLP-16 recording: less than one turn.
  absl::StatusOr<PcapReader> in = PcapReader::Open(EncodedVlp16());
  absl::StatusOr<PcapWriter> w = PcapWriter::Create(dir_ / "short.pcap");
  ASSERT_TRUE(in.ok() && w.ok());
  PcapRecord rec;
  for (int i = 0; i < 100 && *in->Next(&rec); ++i)
    ASSERT_TRUE(w->WriteRecord(rec.time_ns, rec.data).ok());
  ASSERT_TRUE(w->Close().ok());
  const LinecalRun r =
      RunLinecal("lidar decode --model vlp16 --pcap " + (dir_ / "short.pcap").string() + " --out " +
                 (dir_ / "out").string());
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_NE(r.out.find("scans written:       0"), std::string::npos) << r.out;
}

}  // namespace
}  // namespace linecal
