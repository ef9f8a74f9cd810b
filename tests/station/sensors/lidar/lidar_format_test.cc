#include "station/sensors/lidar/lidar_format.h"

#include <cmath>
#include <numbers>
#include <string>

#include "Eigen/Dense"
#include "gtest/gtest.h"
#include "station/io/byte_io.h"
#include "tests/support/external_data.h"

namespace linecal {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

TEST(LidarModelInfo, PacketSizesAddUpFromTheLayouts) {
  // 12 blocks of 100 bytes, u32 time, return mode, product id.
  EXPECT_EQ(vlp16::kBlocks * vlp16::kBlockBytes + 4 + 1 + 1, vlp16::kPacketBytes);
  EXPECT_EQ(vlp16::kBlockBytes,
            4 + vlp16::kFiringsPerBlock * vlp16::kLasers * vlp16::kMeasurementBytes);
  // 8-byte header, 6 blocks of 2 + 64 × 3 bytes, 22-byte tail.
  EXPECT_EQ(pandar64::kTailOffset + 22, pandar64::kPacketBytes);
  EXPECT_EQ(pandar64::kPacketBytes + 4, pandar64::kPacketBytesWithSequence);
  // 12-byte header, 8 blocks of 2 + 32 × 4 bytes, 24-byte tail, u32 sequence number.
  EXPECT_EQ(pandarxt32::kUdpSequenceOffset + 4, pandarxt32::kPacketBytes);
  EXPECT_EQ(pandarxt32::kFactoryOffset + 1, pandarxt32::kUdpSequenceOffset);

  EXPECT_EQ(GetLidarModelInfo(LidarModel::kVlp16).channels, 16);
  EXPECT_EQ(GetLidarModelInfo(LidarModel::kPandar64).packet_bytes_alt, 1198u);
  EXPECT_EQ(GetLidarModelInfo(LidarModel::kPandarXt32).packet_bytes, 1080u);
  EXPECT_EQ(ColumnsPerPacket(LidarModel::kVlp16, 1), 24);
  EXPECT_EQ(ColumnsPerPacket(LidarModel::kVlp16, 2), 12);
  EXPECT_EQ(ColumnsPerPacket(LidarModel::kPandar64, 2), 3);
  EXPECT_EQ(ColumnsPerPacket(LidarModel::kPandarXt32, 1), 8);
}

TEST(LidarModelInfo, NamesRoundTrip) {
  for (LidarModel m : {LidarModel::kVlp16, LidarModel::kPandar64, LidarModel::kPandarXt32}) {
    EXPECT_EQ(LidarModelFromName(GetLidarModelInfo(m).name), m);
  }
  EXPECT_FALSE(LidarModelFromName("vlp32").has_value());
  EXPECT_FALSE(LidarModelFromName("").has_value());
}

TEST(LidarReturnModes, ReturnsPerModeByte) {
  EXPECT_EQ(ReturnsForModeByte(LidarModel::kVlp16, 0x37), 1);
  EXPECT_EQ(ReturnsForModeByte(LidarModel::kVlp16, 0x38), 1);
  EXPECT_EQ(ReturnsForModeByte(LidarModel::kVlp16, 0x39), 2);
  EXPECT_EQ(ReturnsForModeByte(LidarModel::kVlp16, 0x3B), 0);
  EXPECT_EQ(ReturnsForModeByte(LidarModel::kVlp16, 0x00), 0);
  EXPECT_EQ(ReturnsForModeByte(LidarModel::kPandar64, 0x33), 1);
  EXPECT_EQ(ReturnsForModeByte(LidarModel::kPandarXt32, 0x3B), 2);
  EXPECT_EQ(ReturnsForModeByte(LidarModel::kPandarXt32, 0x3C), 2);
  EXPECT_EQ(ReturnsForModeByte(LidarModel::kPandarXt32, 0x3A), 0);
}

TEST(LidarTiming, ColumnAndChannelOffsets) {
  // VLP-16: firing sequences every 55.296 µs from the packet time, lasers 2.304 µs apart.
  EXPECT_EQ(ColumnTimeOffsetNs(LidarModel::kVlp16, 0, 24), 0);
  EXPECT_EQ(ColumnTimeOffsetNs(LidarModel::kVlp16, 23, 24), 23 * 55296);
  EXPECT_EQ(ChannelTimeOffsetNs(LidarModel::kVlp16, 15), 15 * 2304);
  // Pandar64: the packet time is 42.58 µs after the last column.
  EXPECT_EQ(ColumnTimeOffsetNs(LidarModel::kPandar64, 5, 6), -42580);
  EXPECT_EQ(ColumnTimeOffsetNs(LidarModel::kPandar64, 0, 6), -42580 - 5 * 55560);
  EXPECT_EQ(ColumnTimeOffsetNs(LidarModel::kPandar64, 0, 3), -42580 - 2 * 55560);
  EXPECT_EQ(ChannelTimeOffsetNs(LidarModel::kPandar64, 0), -23180);
  EXPECT_EQ(ChannelTimeOffsetNs(LidarModel::kPandar64, 63), -12748);
  // PandarXT-32 protocol 6.1.
  EXPECT_EQ(ColumnTimeOffsetNs(LidarModel::kPandarXt32, 7, 8), 5632);
  EXPECT_EQ(ColumnTimeOffsetNs(LidarModel::kPandarXt32, 0, 4), 5632 - 3 * 50000);
  EXPECT_EQ(ChannelTimeOffsetNs(LidarModel::kPandarXt32, 31), 368 + 31 * 1512);
}

TEST(LidarTiming, NearestTimeCompletesAnHourCounter) {
  constexpr std::int64_t kHour = vlp16::kTimestampPeriodNs;
  const std::int64_t host = 1673400471'737763166;  // 2023-01-11 01:27:51.74 UTC
  const std::int64_t hour_start = host / kHour * kHour;
  // The recorded VLP-16's first packet says 2 min 20.55 s past the hour, 25.5 min before the
  // capture clock's 27 min 51 s: the same hour is nearest.
  EXPECT_EQ(NearestTimeNs(140'554'572'000, kHour, host), hour_start + 140'554'572'000);
  // Just after the top of the hour on the sensor, just before it on the host: next hour.
  EXPECT_EQ(NearestTimeNs(1'000'000'000, kHour, hour_start + kHour - 2'000'000'000),
            hour_start + kHour + 1'000'000'000);
  // The other way round: previous hour.
  EXPECT_EQ(NearestTimeNs(kHour - 1'000'000'000, kHour, hour_start + 3'000'000'000),
            hour_start - 1'000'000'000);
  // Remainders beyond a period are reduced first.
  EXPECT_EQ(NearestTimeNs(kHour + 5, kHour, hour_start + 10), hour_start + 5);
}

TEST(LidarTiming, HesaiDates) {
  // The recorded Pandar64's tail: 78 06 19 0c 02 09 = 2020-06-25 12:02:09 UTC.
  const std::uint8_t recorded[6] = {0x78, 0x06, 0x19, 0x0c, 0x02, 0x09};
  EXPECT_EQ(HesaiUtcSeconds(std::span<const std::uint8_t, 6>(recorded, 6)), 1593086529);
  // Firmware that counts years from 2000 writes 20 for 2020.
  const std::uint8_t from_2000[6] = {20, 6, 25, 12, 2, 9};
  EXPECT_EQ(HesaiUtcSeconds(std::span<const std::uint8_t, 6>(from_2000, 6)), 1593086529);
  const std::uint8_t leap_day[6] = {124, 2, 29, 0, 0, 0};  // 2024-02-29
  EXPECT_EQ(HesaiUtcSeconds(std::span<const std::uint8_t, 6>(leap_day, 6)), 1709164800);
  for (const auto& bad : std::vector<std::array<std::uint8_t, 6>>{{123, 2, 29, 0, 0, 0},
                                                                  {120, 0, 1, 0, 0, 0},
                                                                  {120, 13, 1, 0, 0, 0},
                                                                  {120, 1, 0, 0, 0, 0},
                                                                  {120, 1, 1, 24, 0, 0},
                                                                  {120, 1, 1, 0, 60, 0},
                                                                  {0, 0, 0, 0, 0, 0}}) {
    EXPECT_FALSE(HesaiUtcSeconds(std::span<const std::uint8_t, 6>(bad)).has_value())
        << int(bad[0]) << "-" << int(bad[1]) << "-" << int(bad[2]);
  }
}

TEST(LidarGeometry, FrameAndBaseRotation) {
  // Azimuth 0 is +y, azimuth 90° is +x, elevation up is +z.
  EXPECT_TRUE(LidarPointFromPolar(2.0, 0.0, 0.0).isApprox(Eigen::Vector3d(0, 2, 0)));
  EXPECT_TRUE(LidarPointFromPolar(2.0, 90 * kDeg, 0.0).isApprox(Eigen::Vector3d(2, 0, 0)));
  const Eigen::Vector3d up = LidarPointFromPolar(2.0, 0.0, 30 * kDeg);
  EXPECT_NEAR(up.z(), 1.0, 1e-12);
  EXPECT_NEAR(up.y(), std::sqrt(3.0), 1e-12);
  // A forward-looking LiDAR: its azimuth 0 is the car's forward, its x (azimuth 90°, to the
  // right) the car's -y.
  const Eigen::Matrix3d r = LidarBaseRotation();
  EXPECT_TRUE((r * Eigen::Vector3d::UnitY()).isApprox(Eigen::Vector3d::UnitX()));
  EXPECT_TRUE((r * Eigen::Vector3d::UnitX()).isApprox(-Eigen::Vector3d::UnitY()));
  EXPECT_TRUE((r * Eigen::Vector3d::UnitZ()).isApprox(Eigen::Vector3d::UnitZ()));
  EXPECT_NEAR(r.determinant(), 1.0, 1e-12);

  LidarBeam beam;
  beam.azimuth_offset_rad = 0.5 * kDeg;
  beam.firing_fraction = 0.25;
  EXPECT_NEAR(BeamAzimuthRad(beam, 10 * kDeg, 0.2 * kDeg), (10 + 0.5 + 0.05) * kDeg, 1e-15);
}

TEST(LidarBeamTable, Vlp16Default) {
  const absl::StatusOr<LidarBeamTable> t = DefaultBeamTable(LidarModel::kVlp16);
  ASSERT_TRUE(t.ok()) << t.status();
  ASSERT_EQ(t->beams.size(), 16u);
  EXPECT_TRUE(ValidateBeamTable(*t).ok());
  // Laser 0 is -15° (the lowest), laser 1 is +1° (9th from the bottom), laser 15 is +15°.
  EXPECT_EQ(t->beams[0].ring, 0);
  EXPECT_EQ(t->beams[1].ring, 8);
  EXPECT_EQ(t->beams[14].ring, 7);
  EXPECT_EQ(t->beams[15].ring, 15);
  EXPECT_NEAR(t->beams[2].elevation_rad, -13 * kDeg, 1e-15);
  EXPECT_NEAR(t->beams[15].firing_fraction, 15 * 2.304 / 55.296, 1e-15);
  EXPECT_EQ(t->beams[3].azimuth_offset_rad, 0.0);

  const absl::StatusOr<LidarBeamTable> hesai = DefaultBeamTable(LidarModel::kPandar64);
  EXPECT_EQ(hesai.status().code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_NE(hesai.status().message().find("pandar64"), std::string::npos);
}

// The angle file of the real Pandar64 (docs/external-data.md), written by its maker.
TEST(LidarBeamTable, ReadsTheRecordedPandar64File) {
  LINECAL_EXTERNAL_OR_SKIP(csv, "lidar/pandar64/Pandar64.csv");
  const absl::StatusOr<LidarBeamTable> t = ReadAngleCorrectionCsv(LidarModel::kPandar64, csv);
  ASSERT_TRUE(t.ok()) << t.status();
  ASSERT_EQ(t->beams.size(), 64u);
  // First line "1,14.9,-1.042": channel 1 is the highest beam.
  EXPECT_NEAR(t->beams[0].elevation_rad, 14.9 * kDeg, 1e-15);
  EXPECT_NEAR(t->beams[0].azimuth_offset_rad, -1.042 * kDeg, 1e-15);
  EXPECT_EQ(t->beams[0].ring, 63);
  EXPECT_EQ(t->beams[0].firing_fraction, 0.0);
  EXPECT_TRUE(ValidateBeamTable(*t).ok());
  // Rings are a permutation sorted by elevation.
  for (const LidarBeam& a : t->beams) {
    for (const LidarBeam& b : t->beams) {
      if (a.elevation_rad < b.elevation_rad) {
        EXPECT_LT(a.ring, b.ring);
      }
    }
  }
}

std::string Csv(int channels, int bad_line = -1, const std::string& bad_text = "") {
  std::string s = "Channel,Elevation,Azimuth\r\n";
  for (int c = 1; c <= channels; ++c) {
    s += c == bad_line ? bad_text : std::to_string(c) + "," + std::to_string(c * 0.5 - 8) + ",0.5";
    s += "\n";
  }
  return s;
}

TEST(LidarBeamTable, CsvErrorsNameFileAndLine) {
  EXPECT_TRUE(ParseAngleCorrectionCsv(LidarModel::kPandarXt32, Csv(32), "xt.csv").ok());
  struct Case {
    std::string text;
    std::string message;
  };
  const std::vector<Case> cases = {
      {"", "xt.csv: empty angle correction file"},
      {"1,2,3\n", "xt.csv:1: expected the header"},
      {Csv(31), "xt.csv: found 31 channels, pandarxt32 has 32"},
      {Csv(33), "xt.csv:34: more than 32 channels"},
      {Csv(32, 5, "6,1,0"), "xt.csv:6: channel '6', expected 5"},
      {Csv(32, 5, "5,abc,0"), "xt.csv:6: elevation 'abc' is not a number"},
      {Csv(32, 5, "5,91,0"), "xt.csv:6: elevation '91'"},
      {Csv(32, 5, "5,1,nan"), "xt.csv:6: azimuth 'nan' is not a number"},
      {Csv(32, 5, "5,1"), "xt.csv:6: expected 3 comma-separated fields, found 2"},
  };
  for (const Case& c : cases) {
    const absl::StatusOr<LidarBeamTable> t =
        ParseAngleCorrectionCsv(LidarModel::kPandarXt32, c.text, "xt.csv");
    ASSERT_FALSE(t.ok()) << c.message;
    EXPECT_EQ(t.status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_NE(t.status().message().find(c.message), std::string::npos)
        << t.status().message() << " should contain " << c.message;
  }
  const absl::StatusOr<LidarBeamTable> missing =
      ReadAngleCorrectionCsv(LidarModel::kPandar64, "/nonexistent/angles.csv");
  EXPECT_EQ(missing.status().code(), absl::StatusCode::kNotFound);
  EXPECT_NE(missing.status().message().find("/nonexistent/angles.csv"), std::string::npos);
}

TEST(LidarBeamTable, ValidateRejectsBrokenTables) {
  LidarBeamTable t = *DefaultBeamTable(LidarModel::kVlp16);
  t.beams[3].ring = t.beams[4].ring;
  EXPECT_EQ(ValidateBeamTable(t).code(), absl::StatusCode::kInvalidArgument);
  t = *DefaultBeamTable(LidarModel::kVlp16);
  t.beams[2].elevation_rad = std::nan("");
  EXPECT_EQ(ValidateBeamTable(t).code(), absl::StatusCode::kInvalidArgument);
  t = *DefaultBeamTable(LidarModel::kVlp16);
  t.model = LidarModel::kPandarXt32;
  EXPECT_EQ(ValidateBeamTable(t).code(), absl::StatusCode::kInvalidArgument);
}

std::vector<LidarColumn> Columns(LidarModel model, int returns, int count, double range_m) {
  const int channels = GetLidarModelInfo(model).channels;
  std::vector<LidarColumn> cols(count);
  for (int k = 0; k < count; ++k) {
    cols[k].azimuth_centideg = static_cast<std::uint16_t>(k * 20);
    cols[k].echoes.assign(returns * channels, LidarEcho{range_m, 7});
  }
  return cols;
}

TEST(LidarEncoder, WritesTheVlp16Layout) {
  LidarEncodeSettings s;
  s.model = LidarModel::kVlp16;
  s.return_mode = LidarReturnMode::kDual;
  // 5 min 3.000123 s past the hour.
  s.first_column_time_ns =
      1'700'000'000'000'000'000 / vlp16::kTimestampPeriodNs * vlp16::kTimestampPeriodNs +
      303'000'123'000;
  std::vector<LidarColumn> cols = Columns(s.model, 2, 12, 10.0);
  cols[0].echoes[16 + 3].range_m = 1.234;  // column 0, second return, laser 3
  const auto packets = EncodeLidarPackets(s, cols);
  ASSERT_TRUE(packets.ok()) << packets.status();
  ASSERT_EQ(packets->size(), 1u);
  const std::vector<std::uint8_t>& p = (*packets)[0];
  ASSERT_EQ(p.size(), vlp16::kPacketBytes);
  for (int b = 0; b < vlp16::kBlocks; ++b) {
    EXPECT_EQ(p[b * 100], 0xFF);
    EXPECT_EQ(p[b * 100 + 1], 0xEE);
    // Dual return: blocks 2q and 2q+1 both carry column 2q's azimuth.
    EXPECT_EQ(LoadLe16(&p[b * 100 + 2]), (b / 2) * 2 * 20) << b;
  }
  EXPECT_EQ(LoadLe16(&p[4]), 5000);               // 10 m in 2 mm units
  EXPECT_EQ(LoadLe16(&p[100 + 4 + 3 * 3]), 617);  // 1.234 m → 617 × 2 mm
  EXPECT_EQ(p[6], 7);
  EXPECT_EQ(LoadLe32(&p[vlp16::kTimestampOffset]), 303'000'123u);
  EXPECT_EQ(p[vlp16::kReturnModeOffset], 0x39);
  EXPECT_EQ(p[vlp16::kProductIdOffset], 0x22);
}

TEST(LidarEncoder, WritesTheHesaiLayouts) {
  LidarEncodeSettings s;
  s.model = LidarModel::kPandar64;
  s.return_mode = LidarReturnMode::kStrongest;
  s.first_udp_sequence = 77;
  // 2020-06-25 12:02:09.5 UTC minus the first column's offset from the packet time.
  const std::int64_t packet_ns = 1593086529'500000'000;
  s.first_column_time_ns = packet_ns + ColumnTimeOffsetNs(s.model, 0, 6);
  auto packets = EncodeLidarPackets(s, Columns(s.model, 1, 12, 4.0));
  ASSERT_TRUE(packets.ok()) << packets.status();
  ASSERT_EQ(packets->size(), 2u);
  const std::vector<std::uint8_t>& p = (*packets)[0];
  ASSERT_EQ(p.size(), pandar64::kPacketBytesWithSequence);
  EXPECT_EQ(p[0], 0xEE);
  EXPECT_EQ(p[1], 0xFF);
  EXPECT_EQ(p[pandar64::kLaserCountOffset], 64);
  EXPECT_EQ(p[pandar64::kBlockCountOffset], 6);
  EXPECT_EQ(p[pandar64::kDistanceUnitOffset], 4);
  EXPECT_EQ(LoadLe16(&p[8 + 194]), 20);  // block 1 azimuth
  EXPECT_EQ(LoadLe16(&p[8 + 2]), 1000);  // 4 m in 4 mm units
  EXPECT_EQ(LoadLe32(&p[pandar64::kTimestampOffset]), 500000u);
  const std::uint8_t date[6] = {0x78, 0x06, 0x19, 0x0c, 0x02, 0x09};
  EXPECT_TRUE(std::equal(date, date + 6, &p[pandar64::kDateTimeOffset]));
  EXPECT_EQ(p[pandar64::kReturnModeOffset], 0x37);
  EXPECT_EQ(LoadLe16(&p[pandar64::kMotorSpeedOffset]), 600);
  EXPECT_EQ(LoadLe32(&p[pandar64::kUdpSequenceOffset]), 77u);
  EXPECT_EQ(LoadLe32(&(*packets)[1][pandar64::kUdpSequenceOffset]), 78u);

  s.pandar64_udp_sequence = false;
  packets = EncodeLidarPackets(s, Columns(s.model, 1, 6, 4.0));
  ASSERT_TRUE(packets.ok());
  EXPECT_EQ((*packets)[0].size(), pandar64::kPacketBytes);

  s.model = LidarModel::kPandarXt32;
  s.return_mode = LidarReturnMode::kDual;
  packets = EncodeLidarPackets(s, Columns(s.model, 2, 4, 4.0));
  ASSERT_TRUE(packets.ok()) << packets.status();
  const std::vector<std::uint8_t>& x = (*packets)[0];
  ASSERT_EQ(x.size(), pandarxt32::kPacketBytes);
  EXPECT_EQ(x[pandarxt32::kProtocolMajorOffset], 6);
  EXPECT_EQ(x[pandarxt32::kProtocolMinorOffset], 1);
  EXPECT_EQ(x[pandarxt32::kLaserCountOffset], 32);
  EXPECT_EQ(x[pandarxt32::kBlockCountOffset], 8);
  EXPECT_EQ(x[pandarxt32::kReturnCountOffset], 2);
  EXPECT_EQ(x[pandarxt32::kReturnModeOffset], 0x39);
  EXPECT_EQ(LoadLe16(&x[12 + 130]), 0);   // block 1: the second return of column 0
  EXPECT_EQ(LoadLe16(&x[12 + 260]), 20);  // block 2: column 1
}

TEST(LidarEncoder, RejectsBadInput) {
  LidarEncodeSettings s;
  s.model = LidarModel::kVlp16;
  EXPECT_EQ(EncodeLidarPackets(s, Columns(s.model, 1, 23, 1.0)).status().code(),
            absl::StatusCode::kInvalidArgument);
  std::vector<LidarColumn> cols = Columns(s.model, 1, 24, 1.0);
  cols[3].echoes.pop_back();
  EXPECT_EQ(EncodeLidarPackets(s, cols).status().code(), absl::StatusCode::kInvalidArgument);
  cols = Columns(s.model, 1, 24, 1.0);
  cols[5].azimuth_centideg = 36000;
  EXPECT_EQ(EncodeLidarPackets(s, cols).status().code(), absl::StatusCode::kInvalidArgument);
  cols = Columns(s.model, 1, 24, 1.0);
  cols[5].echoes[2].range_m = -1.0;
  EXPECT_EQ(EncodeLidarPackets(s, cols).status().code(), absl::StatusCode::kInvalidArgument);
  cols[5].echoes[2].range_m = std::nan("");
  EXPECT_EQ(EncodeLidarPackets(s, cols).status().code(), absl::StatusCode::kInvalidArgument);
  // Beyond the 16-bit field (131 m at 2 mm): sent as "no return".
  cols[5].echoes[2].range_m = 200.0;
  const auto packets = EncodeLidarPackets(s, cols);
  ASSERT_TRUE(packets.ok());
  EXPECT_EQ(LoadLe16(&(*packets)[0][200 + 4 + 16 * 3 + 2 * 3]), 0);

  s.model = LidarModel::kPandar64;
  s.first_column_time_ns = 0;  // 1970-01-01: before a Hesai date can start
  EXPECT_EQ(EncodeLidarPackets(s, Columns(s.model, 1, 6, 1.0)).status().code(),
            absl::StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace linecal
