#include "station/sensors/radar/radar_format.h"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <map>
#include <numbers>
#include <random>
#include <regex>
#include <sstream>

#include "tests/support/external_data.h"

namespace linecal {
namespace {

constexpr double kRadPerDeg = std::numbers::pi / 180.0;
// Doubles of raw·factor + offset differ from the decimal value by a few ulps of ~1e3.
constexpr double kFloatSlack = 1e-9;

std::span<const uint8_t> Span(const CanFrame& f) { return f.payload(); }

// ---------------------------------------------------------------------------------------
// Generic signals.

TEST(CanSignalTest, BytesNeeded) {
  EXPECT_EQ(SignalBytesNeeded(ars408::kClusterIdSignal), 1);  // 7|8 big-endian
  EXPECT_EQ(SignalBytesNeeded(ars408::kClusterDistLong), 3);  // 15|13: bytes 1-2
  EXPECT_EQ(SignalBytesNeeded(ars408::kClusterRcs), 8);       // 63|8: byte 7
  EXPECT_EQ(SignalBytesNeeded(ars408::kClusterInterfaceVersion), 5);
  EXPECT_EQ(SignalBytesNeeded(esr::kRollingCount1), 1);            // 6|2 little-endian
  EXPECT_EQ(SignalBytesNeeded(ars408::kClusterMeasCounterLe), 4);  // 16|16 little-endian
}

// docs/sensors.md spells the 0x701 layout as byte arithmetic; that is an oracle independent of
// the DBC bit walk.
TEST(CanSignalTest, MotorolaExtractionMatchesTheByteFormulasOf0x701) {
  std::mt19937 rng(1);  // fixed seed
  std::uniform_int_distribution<int> byte(0, 255);
  for (int trial = 0; trial < 1000; ++trial) {
    std::array<uint8_t, 8> d;
    for (uint8_t& b : d) b = static_cast<uint8_t>(byte(rng));
    const std::span<const uint8_t> p(d);
    EXPECT_EQ(*ExtractRaw(p, ars408::kClusterIdSignal), d[0]);
    EXPECT_EQ(*ExtractRaw(p, ars408::kClusterDistLong), d[1] << 5 | d[2] >> 3);
    EXPECT_EQ(*ExtractRaw(p, ars408::kClusterDistLat), (d[2] & 3) << 8 | d[3]);
    EXPECT_EQ(*ExtractRaw(p, ars408::kClusterVrelLong), d[4] << 2 | d[5] >> 6);
    EXPECT_EQ(*ExtractRaw(p, ars408::kClusterVrelLat), (d[5] & 0x3F) << 3 | d[6] >> 5);
    EXPECT_EQ(*ExtractRaw(p, ars408::kClusterDynProp), d[6] & 7);
    EXPECT_EQ(*ExtractRaw(p, ars408::kClusterRcs), d[7]);
    // The 16-bit counter in bytes 2-3, both byte orders.
    EXPECT_EQ(*ExtractRaw(p, ars408::kClusterMeasCounter), d[2] << 8 | d[3]);
    EXPECT_EQ(*ExtractRaw(p, ars408::kClusterMeasCounterLe), d[2] | d[3] << 8);
    // Little-endian 2 bits at 6: the top two bits of byte 0.
    EXPECT_EQ(*ExtractRaw(p, esr::kRollingCount1), d[0] >> 6);
  }
}

TEST(CanSignalTest, SignedValuesAreSignExtended) {
  std::array<uint8_t, 8> d{};
  // ESR track angle 12|10 signed: byte 1 bits 4..0 then byte 2 bits 7..3. All ones = −1.
  d[1] = 0x1F;
  d[2] = 0xF8;
  EXPECT_EQ(*ExtractRaw(d, esr::kTrackAngle), -1);
  EXPECT_NEAR(*ExtractPhysical(d, esr::kTrackAngle), -0.1, kFloatSlack);
  d[1] = 0x10;  // only the sign bit: the most negative value
  d[2] = 0x00;
  EXPECT_EQ(*ExtractRaw(d, esr::kTrackAngle), -512);
}

TEST(CanSignalTest, ShortPayloadsGiveNoValue) {
  const std::array<uint8_t, 7> d{};
  EXPECT_FALSE(ExtractRaw(d, ars408::kClusterRcs).has_value());
  EXPECT_TRUE(ExtractRaw(d, ars408::kClusterDynProp).has_value());
  std::array<uint8_t, 7> out{};
  EXPECT_EQ(InsertRaw(out, ars408::kClusterRcs, 1).code(), absl::StatusCode::kOutOfRange);
}

TEST(CanSignalTest, RandomInsertExtractRoundTripLeavesOtherBitsAlone) {
  std::mt19937 rng(2);  // fixed seed
  const auto uniform = [&](int lo, int hi) {
    return std::uniform_int_distribution<int>(lo, hi)(rng);
  };
  for (int trial = 0; trial < 20000; ++trial) {
    const int payload_bytes = uniform(1, kCanFdMaxDataBytes);
    CanSignal s{"random",
                0,
                uniform(1, std::min(63, payload_bytes * 8)),
                uniform(0, 1) ? ByteOrder::kBigEndian : ByteOrder::kLittleEndian,
                uniform(0, 1) == 1,
                1,
                0};
    s.start_bit = uniform(0, payload_bytes * 8 - 1);
    if (SignalBytesNeeded(s) > payload_bytes) continue;
    std::vector<uint8_t> before(payload_bytes);
    for (uint8_t& b : before) b = static_cast<uint8_t>(uniform(0, 255));
    const int64_t lo = s.is_signed ? -(int64_t{1} << (s.length - 1)) : 0;
    // In unsigned arithmetic: a 63-bit unsigned signal's top is INT64_MAX, and 2^63 - 1
    // computed in int64 would overflow on the way.
    const int64_t hi = s.is_signed ? (int64_t{1} << (s.length - 1)) - 1
                                   : static_cast<int64_t>((uint64_t{1} << s.length) - 1);
    const int64_t raw = std::uniform_int_distribution<int64_t>(lo, hi)(rng);
    std::vector<uint8_t> after = before;
    ASSERT_TRUE(InsertRaw(after, s, raw).ok());
    ASSERT_EQ(*ExtractRaw(after, s), raw) << "start " << s.start_bit << " len " << s.length;
    // Writing the old value back restores every byte: nothing outside the signal changed.
    ASSERT_TRUE(InsertRaw(after, s, *ExtractRaw(before, s)).ok());
    ASSERT_EQ(after, before);
    if (hi < INT64_MAX) {
      EXPECT_EQ(InsertRaw(after, s, hi + 1).code(), absl::StatusCode::kOutOfRange);
    }
    EXPECT_EQ(InsertRaw(after, s, lo - 1).code(), absl::StatusCode::kOutOfRange);
  }
}

TEST(CanSignalTest, InsertPhysicalRoundsAndRejectsOutOfRange) {
  std::array<uint8_t, 8> d{};
  ASSERT_TRUE(InsertPhysical(d, ars408::kClusterDistLong, 146.29).ok());
  EXPECT_NEAR(*ExtractPhysical(d, ars408::kClusterDistLong), 146.2, kFloatSlack);
  const absl::Status s = InsertPhysical(d, ars408::kClusterDistLong, 1200);
  EXPECT_EQ(s.code(), absl::StatusCode::kOutOfRange);
  EXPECT_NE(s.message().find("Cluster_DistLong"), std::string::npos) << s;
  EXPECT_EQ(InsertPhysical(d, ars408::kClusterDistLong, std::nan("")).code(),
            absl::StatusCode::kOutOfRange);
}

// ---------------------------------------------------------------------------------------
// ARS408.

TEST(Ars408Test, WorkedExampleOfSensorsMd) {
  // 701#0564FE8E800160A4 → id 5, DistLong 146.2 m, DistLat 28.5 m, RCS 18 dBm²,
  // range 148.95 m, azimuth 11.03°.
  const std::array<uint8_t, 8> d{0x05, 0x64, 0xFE, 0x8E, 0x80, 0x01, 0x60, 0xA4};
  const std::optional<Ars408Target> t = DecodeArs408Target(d, RadarDetectionKind::kCluster);
  ASSERT_TRUE(t.has_value());
  EXPECT_EQ(t->id, 5);
  EXPECT_NEAR(t->dist_long_m, 146.2, kFloatSlack);
  EXPECT_NEAR(t->dist_lat_m, 28.5, kFloatSlack);
  EXPECT_NEAR(t->rcs_dbsm, 18.0, kFloatSlack);
  // From the byte formulas: VrelLong = 0x80<<2 | 0x01>>6 = 512 → 0; VrelLat = 1<<3 | 3 = 11
  // → −61.25; DynProp = 0x60 & 7 = 0.
  EXPECT_NEAR(t->vrel_long_mps, 0.0, kFloatSlack);
  EXPECT_NEAR(t->vrel_lat_mps, -61.25, kFloatSlack);
  EXPECT_EQ(t->dyn_prop, 0);
  const RadarDetection det = Ars408TargetToDetection(*t, RadarDetectionKind::kCluster, {});
  constexpr double kPrintedDigits = 0.005;  // docs/sensors.md rounds to two decimals
  EXPECT_NEAR(det.range_m, 148.95, kPrintedDigits);
  EXPECT_NEAR(det.azimuth_rad / kRadPerDeg, 11.03, kPrintedDigits);
  EXPECT_NEAR(det.range_rate_mps, -61.25 * 28.5 / std::hypot(146.2, 28.5), kFloatSlack);
  ASSERT_TRUE(det.rcs_dbsm.has_value());
  EXPECT_NEAR(*det.rcs_dbsm, 18.0, kFloatSlack);
}

TEST(Ars408Test, ClassifiesIdsWithSensorOffset) {
  EXPECT_EQ(ClassifyArs408Id(0x600)->message, Ars408Message::kClusterStatus);
  EXPECT_EQ(ClassifyArs408Id(0x600)->sensor_id, 0);
  EXPECT_EQ(ClassifyArs408Id(0x771)->message, Ars408Message::kClusterGeneral);
  EXPECT_EQ(ClassifyArs408Id(0x771)->sensor_id, 7);
  EXPECT_EQ(ClassifyArs408Id(0x722)->message, Ars408Message::kClusterQuality);
  EXPECT_EQ(ClassifyArs408Id(0x722)->sensor_id, 2);
  EXPECT_EQ(ClassifyArs408Id(0x63A)->message, Ars408Message::kObjectStatus);
  EXPECT_EQ(ClassifyArs408Id(0x63A)->sensor_id, 3);
  EXPECT_EQ(ClassifyArs408Id(0x65B)->message, Ars408Message::kObjectGeneral);
  EXPECT_EQ(ClassifyArs408Id(0x65B)->sensor_id, 5);
  for (uint32_t id : {0x200u, 0x201u, 0x60Cu, 0x60Du, 0x700u, 0x680u, 0x781u, 0x500u}) {
    EXPECT_FALSE(ClassifyArs408Id(id).has_value()) << std::hex << id;
  }
}

TEST(Ars408Test, ListStatusCounterByteOrderIsAConvention) {
  const Ars408ListStatus status{12, 3, 0x1234, 4};
  RadarConventions big;
  RadarConventions little;
  little.ars408_counter_byte_order = ByteOrder::kLittleEndian;
  const CanFrame fb = *EncodeArs408ListStatus(status, RadarDetectionKind::kCluster, 2, big);
  EXPECT_EQ(fb.id, 0x620u);
  EXPECT_EQ(fb.len, 5);
  EXPECT_EQ(fb.data[0], 12);
  EXPECT_EQ(fb.data[1], 3);
  EXPECT_EQ(fb.data[2], 0x12);
  EXPECT_EQ(fb.data[3], 0x34);
  EXPECT_EQ(fb.data[4] >> 4, 4);
  const CanFrame fl = *EncodeArs408ListStatus(status, RadarDetectionKind::kCluster, 2, little);
  EXPECT_EQ(fl.data[2], 0x34);
  EXPECT_EQ(fl.data[3], 0x12);
  EXPECT_EQ(DecodeArs408ListStatus(Span(fl), RadarDetectionKind::kCluster, little)->meas_counter,
            0x1234u);
  EXPECT_EQ(DecodeArs408ListStatus(Span(fl), RadarDetectionKind::kCluster, big)->meas_counter,
            0x3412u);
  // Objects: NofObjects byte 0, counter bytes 1-2, version in byte 3.
  const CanFrame fo =
      *EncodeArs408ListStatus({40, 0, 0xBEEF, 2}, RadarDetectionKind::kObject, 0, big);
  EXPECT_EQ(fo.id, 0x60Au);
  EXPECT_EQ(fo.data[0], 40);
  EXPECT_EQ(fo.data[1], 0xBE);
  EXPECT_EQ(fo.data[2], 0xEF);
  const Ars408ListStatus back = *DecodeArs408ListStatus(Span(fo), RadarDetectionKind::kObject, big);
  EXPECT_EQ(back.near_count, 40);
  EXPECT_EQ(back.meas_counter, 0xBEEFu);
  EXPECT_EQ(back.interface_version, 2);
  EXPECT_FALSE(DecodeArs408ListStatus(std::span<const uint8_t>(fo.data.data(), 3),
                                      RadarDetectionKind::kObject, big)
                   .has_value());
}

TEST(Ars408Test, ObjectLateralSignIsAConvention) {
  RadarDetection d;
  d.kind = RadarDetectionKind::kObject;
  d.id = 9;
  d.range_m = 20;
  d.azimuth_rad = 30 * kRadPerDeg;  // to the left
  d.rcs_dbsm = 5;
  RadarConventions left;
  RadarConventions right;
  right.ars408_object_lat_left_positive = false;
  EXPECT_GT(Ars408TargetFromDetection(d, left).dist_lat_m, 0);
  EXPECT_LT(Ars408TargetFromDetection(d, right).dist_lat_m, 0);
  const CanFrame f =
      *EncodeArs408Target(Ars408TargetFromDetection(d, right), RadarDetectionKind::kObject, 0);
  const Ars408Target t = *DecodeArs408Target(Span(f), RadarDetectionKind::kObject);
  constexpr double kQuantisedAngleRad = 0.01;  // 0.2 m steps at 20 m
  EXPECT_NEAR(Ars408TargetToDetection(t, RadarDetectionKind::kObject, right).azimuth_rad,
              d.azimuth_rad, kQuantisedAngleRad);
  EXPECT_NEAR(Ars408TargetToDetection(t, RadarDetectionKind::kObject, left).azimuth_rad,
              -d.azimuth_rad, kQuantisedAngleRad);
  // Clusters ignore the object convention.
  d.kind = RadarDetectionKind::kCluster;
  EXPECT_GT(Ars408TargetFromDetection(d, right).dist_lat_m, 0);
}

double Uniform(std::mt19937& rng, double lo, double hi) {
  return std::uniform_real_distribution<double>(lo, hi)(rng);
}

TEST(Ars408Test, RandomTargetsRoundTripWithinHalfAStep) {
  std::mt19937 rng(3);  // fixed seed
  for (RadarDetectionKind kind : {RadarDetectionKind::kCluster, RadarDetectionKind::kObject}) {
    const bool obj = kind == RadarDetectionKind::kObject;
    for (int trial = 0; trial < 5000; ++trial) {
      Ars408Target t;
      t.id = static_cast<int>(Uniform(rng, 0, 255.99));
      t.dist_long_m = Uniform(rng, -500, 1138.2);
      t.dist_lat_m = obj ? Uniform(rng, -204.6, 204.8) : Uniform(rng, -102.3, 102.3);
      t.vrel_long_mps = Uniform(rng, -128, 127.75);
      t.vrel_lat_mps = Uniform(rng, -64, 63.75);
      t.dyn_prop = static_cast<int>(Uniform(rng, 0, 7.99));
      t.rcs_dbsm = Uniform(rng, -64, 63.5);
      const int sensor = static_cast<int>(Uniform(rng, 0, 7.99));
      const absl::StatusOr<CanFrame> f = EncodeArs408Target(t, kind, sensor);
      ASSERT_TRUE(f.ok()) << f.status();
      EXPECT_EQ(f->id, (obj ? 0x60Bu : 0x701u) + 0x10u * static_cast<uint32_t>(sensor));
      EXPECT_EQ(f->len, 8);
      const Ars408Target b = *DecodeArs408Target(Span(*f), kind);
      EXPECT_EQ(b.id, t.id);
      EXPECT_EQ(b.dyn_prop, t.dyn_prop);
      // Half a quantisation step: 0.2 m, 0.25 m/s, 0.5 dBm² signals.
      EXPECT_LE(std::abs(b.dist_long_m - t.dist_long_m), 0.1 + kFloatSlack);
      EXPECT_LE(std::abs(b.dist_lat_m - t.dist_lat_m), 0.1 + kFloatSlack);
      EXPECT_LE(std::abs(b.vrel_long_mps - t.vrel_long_mps), 0.125 + kFloatSlack);
      EXPECT_LE(std::abs(b.vrel_lat_mps - t.vrel_lat_mps), 0.125 + kFloatSlack);
      EXPECT_LE(std::abs(b.rcs_dbsm - t.rcs_dbsm), 0.25 + kFloatSlack);
    }
  }
}

TEST(Ars408Test, RandomQualityRoundTrip) {
  std::mt19937 rng(4);  // fixed seed
  const auto uniform = [&](int lo, int hi) {
    return std::uniform_int_distribution<int>(lo, hi)(rng);
  };
  for (int trial = 0; trial < 1000; ++trial) {
    const Ars408ClusterQuality q{uniform(0, 31), uniform(0, 31), uniform(0, 7), uniform(0, 7),
                                 uniform(0, 31)};
    const int id = uniform(0, 255);
    const CanFrame f = *EncodeArs408ClusterQuality(id, q, 1);
    EXPECT_EQ(f.id, 0x712u);
    const auto [back_id, back] = *DecodeArs408ClusterQuality(Span(f));
    EXPECT_EQ(back_id, id);
    EXPECT_EQ(back.dist_long_rms, q.dist_long_rms);
    EXPECT_EQ(back.dist_lat_rms, q.dist_lat_rms);
    EXPECT_EQ(back.pdh0, q.pdh0);
    EXPECT_EQ(back.ambig_state, q.ambig_state);
    EXPECT_EQ(back.invalid_state, q.invalid_state);
  }
}

TEST(Ars408Test, EncoderErrorsNameTheProblem) {
  Ars408Target t;
  EXPECT_EQ(EncodeArs408Target(t, RadarDetectionKind::kCluster, 8).status().code(),
            absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(EncodeArs408Target(t, RadarDetectionKind::kTrack, 0).status().code(),
            absl::StatusCode::kInvalidArgument);
  t.dist_lat_m = 150;  // the cluster DistLat reaches ±102.3 m only
  const absl::Status s = EncodeArs408Target(t, RadarDetectionKind::kCluster, 0).status();
  EXPECT_EQ(s.code(), absl::StatusCode::kOutOfRange);
  EXPECT_NE(s.message().find("Cluster_DistLat"), std::string::npos) << s;
  RadarCycle cycle;
  cycle.detections.resize(1);
  cycle.detections[0].range_m = 10;  // no rcs_dbsm
  EXPECT_EQ(EncodeArs408Cycle(cycle, "can0", {}).status().code(),
            absl::StatusCode::kInvalidArgument);
}

TEST(Ars408Test, CycleEncoderWritesStatusGeneralAndQualityFrames) {
  RadarCycle cycle;
  cycle.time = CanTime(std::chrono::seconds(100));
  cycle.sensor_id = 1;
  cycle.counter = 77;
  for (int i = 0; i < 3; ++i) {
    RadarDetection d;
    d.id = i;
    d.range_m = 10 + i;
    d.rcs_dbsm = 10;
    if (i == 1) d.cluster_quality = Ars408ClusterQuality{1, 2, 3, 4, 5};
    cycle.detections.push_back(d);
  }
  const std::vector<CanFrame> frames = *EncodeArs408Cycle(cycle, "can3", {});
  ASSERT_EQ(frames.size(), 5u);
  EXPECT_EQ(frames[0].id, 0x610u);
  EXPECT_EQ(frames[0].data[0], 3);  // all clusters reported near
  EXPECT_EQ(frames[1].id, 0x711u);
  EXPECT_EQ(frames[3].id, 0x711u);
  EXPECT_EQ(frames[4].id, 0x712u);
  EXPECT_EQ(frames[4].data[0], 1);  // quality of cluster 1
  for (size_t i = 0; i < frames.size(); ++i) {
    EXPECT_EQ(frames[i].interface, "can3");
    EXPECT_EQ(frames[i].time, cycle.time + kRadarFrameSpacing * static_cast<int64_t>(i));
    EXPECT_TRUE(ValidateCanFrame(frames[i]).ok());
  }
}

// ---------------------------------------------------------------------------------------
// ESR, checked against opendbc's ESR.dbc.

struct DbcSignal {
  std::string name;
  int start_bit;
  int length;
  ByteOrder byte_order;
  bool is_signed;
  double factor;
  double offset;
};

struct DbcMessage {
  std::string name;
  int length;
  std::vector<DbcSignal> signals;
};

// Enough of the DBC grammar for BO_ and SG_ lines (no multiplexing in ESR.dbc).
std::map<uint32_t, DbcMessage> ParseDbc(const std::string& path) {
  std::ifstream in(path);
  EXPECT_TRUE(in.good()) << path;
  const std::regex message(R"(^BO_ (\d+) (\w+): (\d+) )");
  const std::regex signal(
      R"(^ SG_ (\w+) : (\d+)\|(\d+)@([01])([+-]) \(([-0-9.eE+]+),([-0-9.eE+]+)\))");
  std::map<uint32_t, DbcMessage> messages;
  DbcMessage* current = nullptr;
  std::string line;
  std::smatch m;
  while (std::getline(in, line)) {
    if (std::regex_search(line, m, message)) {
      current = &messages[static_cast<uint32_t>(std::stoul(m[1]))];
      current->name = m[2];
      current->length = std::stoi(m[3]);
    } else if (current != nullptr && std::regex_search(line, m, signal)) {
      current->signals.push_back({m[1], std::stoi(m[2]), std::stoi(m[3]),
                                  m[4] == "0" ? ByteOrder::kBigEndian : ByteOrder::kLittleEndian,
                                  m[5] == "-", std::stod(m[6]), std::stod(m[7])});
    } else if (line.empty()) {
      current = nullptr;
    }
  }
  return messages;
}

void ExpectSameSignals(const DbcMessage& dbc, std::span<const CanSignal> ours) {
  ASSERT_EQ(dbc.signals.size(), ours.size()) << dbc.name;
  for (const DbcSignal& d : dbc.signals) {
    const auto it = std::find_if(ours.begin(), ours.end(),
                                 [&](const CanSignal& s) { return d.name == s.name; });
    ASSERT_NE(it, ours.end()) << dbc.name << " " << d.name;
    EXPECT_EQ(it->start_bit, d.start_bit) << dbc.name << " " << d.name;
    EXPECT_EQ(it->length, d.length) << dbc.name << " " << d.name;
    EXPECT_EQ(it->byte_order, d.byte_order) << dbc.name << " " << d.name;
    EXPECT_EQ(it->is_signed, d.is_signed) << dbc.name << " " << d.name;
    EXPECT_DOUBLE_EQ(it->factor, d.factor) << dbc.name << " " << d.name;
    EXPECT_DOUBLE_EQ(it->offset, d.offset) << dbc.name << " " << d.name;
  }
}

TEST(EsrDbcTest, ConstantsMatchEveryTrackAndStatusSignalOfTheDbc) {
  LINECAL_EXTERNAL_OR_SKIP(esr_dbc, "radar/ESR.dbc");
  const std::map<uint32_t, DbcMessage> dbc = ParseDbc(esr_dbc);
  for (int n = 1; n <= esr::kTrackCount; ++n) {
    const uint32_t id = esr::kFirstTrackId + static_cast<uint32_t>(n - 1);
    ASSERT_TRUE(dbc.contains(id)) << std::hex << id;
    const DbcMessage& m = dbc.at(id);
    EXPECT_EQ(m.name, "Target" + std::to_string(n));
    EXPECT_EQ(m.length, 8);
    ExpectSameSignals(m, esr::kTrackSignals);
  }
  ASSERT_TRUE(dbc.contains(esr::kStatusId));
  EXPECT_EQ(dbc.at(esr::kStatusId).name, "ESR_Status");
  ExpectSameSignals(dbc.at(esr::kStatusId), esr::kStatusSignals);
}

// Frames built with the DBC's own definitions (not our constants) decode to the same values.
TEST(EsrDbcTest, FramesBuiltFromTheDbcDecode) {
  LINECAL_EXTERNAL_OR_SKIP(esr_dbc, "radar/ESR.dbc");
  const std::map<uint32_t, DbcMessage> dbc = ParseDbc(esr_dbc);
  std::mt19937 rng(5);  // fixed seed
  for (int trial = 0; trial < 500; ++trial) {
    const int n = static_cast<int>(Uniform(rng, 1, 64.99));
    const DbcMessage& m = dbc.at(esr::kFirstTrackId + static_cast<uint32_t>(n - 1));
    std::array<uint8_t, 8> payload{};
    std::map<std::string, double> values;
    for (const DbcSignal& d : m.signals) {
      const CanSignal s{d.name.c_str(), d.start_bit, d.length, d.byte_order,
                        d.is_signed,    d.factor,    d.offset};
      const int64_t lo = d.is_signed ? -(int64_t{1} << (d.length - 1)) : 0;
      const int64_t hi =
          d.is_signed ? (int64_t{1} << (d.length - 1)) - 1 : (int64_t{1} << d.length) - 1;
      const int64_t raw = std::uniform_int_distribution<int64_t>(lo, hi)(rng);
      ASSERT_TRUE(InsertRaw(payload, s, raw).ok());
      values[d.name] = static_cast<double>(raw) * d.factor + d.offset;
    }
    const EsrTrack t = *DecodeEsrTrack(payload, n);
    EXPECT_EQ(t.number, n);
    EXPECT_EQ(t.status, values["CAN_TX_TRACK_STATUS"]);
    EXPECT_NEAR(t.range_m, values["CAN_TX_TRACK_RANGE"], kFloatSlack);
    EXPECT_NEAR(t.angle_rad, values["CAN_TX_TRACK_ANGLE"] * kRadPerDeg, kFloatSlack);
    EXPECT_NEAR(t.range_rate_mps, values["CAN_TX_TRACK_RANGE_RATE"], kFloatSlack);
    EXPECT_NEAR(t.range_accel_mps2, values["CAN_TX_TRACK_RANGE_ACCEL"], kFloatSlack);
    EXPECT_NEAR(t.width_m, values["CAN_TX_TRACK_WIDTH"], kFloatSlack);
    EXPECT_NEAR(t.lat_rate_mps, values["CAN_TX_TRACK_LAT_RATE"], kFloatSlack);
    EXPECT_EQ(t.med_range_mode, values["CAN_TX_TRACK_MED_RANGE_MODE"]);
    EXPECT_EQ(t.rolling_count, values["CAN_TX_TRACK_ROLLING_COUNT"]);
    EXPECT_EQ(t.oncoming, values["CAN_TX_TRACK_ONCOMING"] != 0);
    EXPECT_EQ(t.grouping_changed, values["CAN_TX_TRACK_GROUPING_CHANGED"] != 0);
    EXPECT_EQ(t.bridge_object, values["CAN_TX_TRACK_BRIDGE_OBJECT"] != 0);
  }
}

TEST(EsrTest, RandomTracksRoundTripWithinHalfAStep) {
  std::mt19937 rng(6);  // fixed seed
  for (int trial = 0; trial < 5000; ++trial) {
    EsrTrack t;
    t.number = static_cast<int>(Uniform(rng, 1, 64.99));
    t.status = static_cast<int>(Uniform(rng, 0, 7.99));
    t.range_m = Uniform(rng, 0, 204.7);
    t.angle_rad = Uniform(rng, -51.2, 51.1) * kRadPerDeg;
    t.range_rate_mps = Uniform(rng, -81.92, 81.91);
    t.range_accel_mps2 = Uniform(rng, -25.6, 25.55);
    t.width_m = Uniform(rng, 0, 7.5);
    t.lat_rate_mps = Uniform(rng, -8, 7.75);
    t.med_range_mode = static_cast<int>(Uniform(rng, 0, 3.99));
    t.rolling_count = trial % 2;
    t.oncoming = trial % 3 == 0;
    t.grouping_changed = trial % 5 == 0;
    t.bridge_object = trial % 7 == 0;
    const absl::StatusOr<CanFrame> f = EncodeEsrTrack(t);
    ASSERT_TRUE(f.ok()) << f.status();
    EXPECT_EQ(f->id, 0x4FFu + static_cast<uint32_t>(t.number));
    const EsrTrack b = *DecodeEsrTrack(Span(*f), t.number);
    EXPECT_EQ(b.status, t.status);
    // Half a step of each signal's factor.
    EXPECT_LE(std::abs(b.range_m - t.range_m), 0.05 + kFloatSlack);
    EXPECT_LE(std::abs(b.angle_rad - t.angle_rad), 0.05 * kRadPerDeg + kFloatSlack);
    EXPECT_LE(std::abs(b.range_rate_mps - t.range_rate_mps), 0.005 + kFloatSlack);
    EXPECT_LE(std::abs(b.range_accel_mps2 - t.range_accel_mps2), 0.025 + kFloatSlack);
    EXPECT_LE(std::abs(b.width_m - t.width_m), 0.25 + kFloatSlack);
    EXPECT_LE(std::abs(b.lat_rate_mps - t.lat_rate_mps), 0.125 + kFloatSlack);
    EXPECT_EQ(b.med_range_mode, t.med_range_mode);
    EXPECT_EQ(b.rolling_count, t.rolling_count);
    EXPECT_EQ(b.oncoming, t.oncoming);
    EXPECT_EQ(b.grouping_changed, t.grouping_changed);
    EXPECT_EQ(b.bridge_object, t.bridge_object);
  }
}

TEST(EsrTest, StatusRoundTrip) {
  EsrStatus s;
  s.scan_index = 54321;
  s.rolling_count = 2;
  s.dsp_timestamp_s = 0.118;
  s.comm_error = true;
  s.radius_curvature_m = -1234;
  s.yaw_rate_radps = -0.5;
  s.vehicle_speed_mps = 22.3;
  const CanFrame f = *EncodeEsrStatus(s);
  EXPECT_EQ(f.id, 0x4E0u);
  EXPECT_EQ(f.data[3], 54321 >> 8);  // scan index 31|16: bytes 3-4 big-endian
  EXPECT_EQ(f.data[4], 54321 & 0xFF);
  EXPECT_EQ(f.data[0] >> 6, 2);  // rolling count 6|2@1: the top bits of byte 0
  const EsrStatus b = *DecodeEsrStatus(Span(f));
  EXPECT_EQ(b.scan_index, s.scan_index);
  EXPECT_EQ(b.rolling_count, s.rolling_count);
  EXPECT_NEAR(b.dsp_timestamp_s, s.dsp_timestamp_s, 0.001 + kFloatSlack);  // 2 ms steps
  EXPECT_TRUE(b.comm_error);
  EXPECT_NEAR(b.radius_curvature_m, s.radius_curvature_m, kFloatSlack);
  EXPECT_NEAR(b.yaw_rate_radps, s.yaw_rate_radps, 0.03125 * kRadPerDeg + kFloatSlack);
  EXPECT_NEAR(b.vehicle_speed_mps, s.vehicle_speed_mps, 0.03125 + kFloatSlack);
}

TEST(EsrTest, AngleSignIsAConvention) {
  EsrTrack t;
  t.angle_rad = 10 * kRadPerDeg;  // clockwise-positive: 10° to the right
  t.range_m = 50;
  RadarConventions clockwise;
  RadarConventions counter;
  counter.esr_angle_clockwise_positive = false;
  EXPECT_NEAR(EsrTrackToDetection(t, clockwise).azimuth_rad, -10 * kRadPerDeg, kFloatSlack);
  EXPECT_NEAR(EsrTrackToDetection(t, counter).azimuth_rad, 10 * kRadPerDeg, kFloatSlack);
  EXPECT_LT(EsrTrackToDetection(t, clockwise).y_m(), 0);
}

TEST(EsrTest, ScanEncoderFillsAll64SlotsAndRejectsBadIds) {
  RadarCycle cycle;
  cycle.kind = RadarDetectionKind::kTrack;
  cycle.counter = 9;
  RadarDetection d;
  d.kind = RadarDetectionKind::kTrack;
  d.id = 64;
  d.range_m = 30;
  cycle.detections.push_back(d);
  const std::vector<CanFrame> frames = *EncodeEsrScan(cycle, "can1", {});
  ASSERT_EQ(frames.size(), 65u);
  EXPECT_EQ(frames[0].id, 0x4E0u);
  EXPECT_EQ(DecodeEsrStatus(Span(frames[0]))->scan_index, 9u);
  for (int n = 1; n <= 64; ++n) {
    const EsrTrack t = *DecodeEsrTrack(Span(frames[n]), n);
    EXPECT_EQ(frames[n].id, 0x4FFu + static_cast<uint32_t>(n));
    EXPECT_EQ(t.status, n == 64 ? esr::kUpdatedTarget : esr::kNoTarget);
  }
  cycle.detections.push_back(d);  // id 64 twice
  EXPECT_EQ(EncodeEsrScan(cycle, "can1", {}).status().code(), absl::StatusCode::kInvalidArgument);
  cycle.detections.back().id = 65;
  EXPECT_EQ(EncodeEsrScan(cycle, "can1", {}).status().code(), absl::StatusCode::kInvalidArgument);
  cycle.detections.pop_back();
  cycle.detections[0].range_m = 300;  // beyond 204.7 m
  const absl::Status s = EncodeEsrScan(cycle, "can1", {}).status();
  EXPECT_EQ(s.code(), absl::StatusCode::kOutOfRange);
  EXPECT_NE(s.message().find("CAN_TX_TRACK_RANGE"), std::string::npos) << s;
}

}  // namespace
}  // namespace linecal
