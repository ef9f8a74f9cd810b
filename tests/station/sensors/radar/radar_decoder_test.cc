#include "station/sensors/radar/radar_decoder.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <numbers>
#include <random>

#include "tests/support/scoped_path.h"

namespace linecal {
namespace {

constexpr double kRadPerDeg = std::numbers::pi / 180.0;
constexpr double kFloatSlack = 1e-9;  // a few ulps of values up to ~1e3

std::vector<CanFrame> Parse(const std::string& text) {
  absl::StatusOr<std::vector<CanFrame>> frames = ParseCandumpLog(text, "test");
  EXPECT_TRUE(frames.ok()) << frames.status();
  return frames.ok() ? *frames : std::vector<CanFrame>{};
}

int64_t Skipped(const RadarDecodeStats& s, RadarSkipReason r) { return s.skipped_for(r); }

TEST(RadarDecoderTest, ParsesModelNames) {
  EXPECT_EQ(ParseRadarModel("ars408"), RadarModel::kArs408);
  EXPECT_EQ(ParseRadarModel("esr"), RadarModel::kEsr);
  EXPECT_FALSE(ParseRadarModel("ARS408").has_value());
  EXPECT_FALSE(ParseRadarModel("").has_value());
}

TEST(RadarDecoderTest, WorkedExampleAsALog) {
  // One cluster announced (near 1, far 0, counter 0x0102), then docs/sensors.md's 0x701 example.
  const std::vector<CanFrame> frames = Parse(
      "(1600000000.000000) can0 600#0100010210\n"
      "(1600000000.000250) can0 701#0564FE8E800160A4\n");
  const RadarDecodeResult r = DecodeRadarFrames(frames, RadarModel::kArs408, {});
  ASSERT_EQ(r.cycles.size(), 1u);
  const RadarCycle& c = r.cycles[0];
  EXPECT_EQ(c.time, frames[0].time);
  EXPECT_EQ(c.kind, RadarDetectionKind::kCluster);
  EXPECT_EQ(c.sensor_id, 0);
  EXPECT_EQ(c.counter, 0x0102u);
  EXPECT_TRUE(c.complete());
  ASSERT_EQ(c.detections.size(), 1u);
  const RadarDetection& d = c.detections[0];
  constexpr double kPrintedDigits = 0.005;  // docs/sensors.md rounds to two decimals
  EXPECT_EQ(d.id, 5);
  EXPECT_NEAR(d.x_m(), 146.2, kFloatSlack);
  EXPECT_NEAR(d.y_m(), 28.5, kFloatSlack);
  EXPECT_NEAR(d.range_m, 148.95, kPrintedDigits);
  EXPECT_NEAR(d.azimuth_rad / kRadPerDeg, 11.03, kPrintedDigits);
  EXPECT_NEAR(*d.rcs_dbsm, 18.0, kFloatSlack);
  EXPECT_EQ(r.stats.frames_read, 2);
  EXPECT_EQ(r.stats.frames_decoded, 2);
  EXPECT_EQ(r.stats.skipped_total(), 0);
  EXPECT_EQ(r.stats.cycles, 1);
  EXPECT_EQ(r.stats.detections, 1);
}

TEST(RadarDecoderTest, SkipsAndCountsEveryKindOfUselessFrame) {
  const std::vector<CanFrame> frames = Parse(
      "(1.000000) can0 701#0564FE8E800160A4\n"       // before any status: no_cycle_header
      "(1.000100) can0 702#0500000000\n"             // likewise
      "(1.001000) can0 600#0200000010\n"             // status: 2 clusters
      "(1.001100) can0 701#R\n"                      // remote
      "(1.001200) can0 20000004#0004000000000000\n"  // error frame
      "(1.001300) can0 00000701#0564FE8E800160A4\n"  // 29-bit id: unknown
      "(1.001400) can0 201#0000000000000000\n"       // RadarState: not decoded, unknown
      "(1.001500) can0 701#0564\n"                   // short
      "(1.001600) can0 701#0564FE8E800160A4\n"       // cluster 5
      "(1.001700) can0 701#0564FE8E800160A4\n"       // cluster 5 again: duplicate
      "(1.001800) can0 702#0700000000\n"             // quality of cluster 7: unmatched
      "(1.001900) can0 702#05F8000000\n"             // quality of cluster 5
      "(1.002000) can0 702#05F8000000\n"             // again: duplicate
      "(1.002100) can0 600#00\n");                   // short status
  const RadarDecodeResult r = DecodeRadarFrames(frames, RadarModel::kArs408, {});
  const RadarDecodeStats& s = r.stats;
  EXPECT_EQ(s.frames_read, 14);
  EXPECT_EQ(s.frames_decoded, 3);
  EXPECT_EQ(Skipped(s, RadarSkipReason::kNoCycleHeader), 2);
  EXPECT_EQ(Skipped(s, RadarSkipReason::kRemote), 1);
  EXPECT_EQ(Skipped(s, RadarSkipReason::kErrorFrame), 1);
  EXPECT_EQ(Skipped(s, RadarSkipReason::kUnknownId), 2);
  EXPECT_EQ(Skipped(s, RadarSkipReason::kShort), 2);
  EXPECT_EQ(Skipped(s, RadarSkipReason::kDuplicate), 2);
  EXPECT_EQ(Skipped(s, RadarSkipReason::kUnmatchedQuality), 1);
  EXPECT_EQ(s.frames_decoded + s.skipped_total(), s.frames_read);
  ASSERT_EQ(r.cycles.size(), 1u);
  EXPECT_FALSE(r.cycles[0].complete());  // 2 announced, 1 arrived
  EXPECT_EQ(s.incomplete_cycles, 1);
  ASSERT_EQ(r.cycles[0].detections.size(), 1u);
  // 05 F8 00: DistLong_rms = 0xF8 >> 3 = 31, DistLat_rms = (0xF8 & 7) << 2 | 0x00 >> 6 = 0.
  ASSERT_TRUE(r.cycles[0].detections[0].cluster_quality.has_value());
  EXPECT_EQ(r.cycles[0].detections[0].cluster_quality->dist_long_rms, 31);
  EXPECT_EQ(r.cycles[0].detections[0].cluster_quality->dist_lat_rms, 0);
}

TEST(RadarDecoderTest, CounterByteOrderIsConfigurable) {
  const std::vector<CanFrame> frames = Parse("(1.0) can0 600#0000123410\n");
  RadarConventions little;
  little.ars408_counter_byte_order = ByteOrder::kLittleEndian;
  EXPECT_EQ(DecodeRadarFrames(frames, RadarModel::kArs408, {}).cycles.at(0).counter, 0x1234u);
  EXPECT_EQ(DecodeRadarFrames(frames, RadarModel::kArs408, little).cycles.at(0).counter, 0x3412u);
}

TEST(RadarDecoderTest, StreamingClosesArsCyclesAtTheNextStatusAndEsrScansAtSlot64) {
  RadarDecoder ars(RadarModel::kArs408, {});
  std::vector<RadarCycle> closed;
  for (const CanFrame& f : Parse("(1.0) can0 600#0100000110\n(1.1) can0 701#0564FE8E800160A4\n")) {
    ars.Push(f, &closed);
  }
  EXPECT_TRUE(closed.empty());  // quality frames may still follow
  for (const CanFrame& f : Parse("(2.0) can0 600#0000000210\n")) ars.Push(f, &closed);
  ASSERT_EQ(closed.size(), 1u);
  EXPECT_EQ(closed[0].counter, 1u);
  ars.Finish(&closed);
  ASSERT_EQ(closed.size(), 2u);
  EXPECT_EQ(closed[1].counter, 2u);
  EXPECT_TRUE(closed[1].complete());  // zero announced, zero arrived

  RadarCycle scan;
  scan.kind = RadarDetectionKind::kTrack;
  scan.counter = 7;
  const std::vector<CanFrame> frames = *EncodeEsrScan(scan, "can0", {});
  RadarDecoder esr(RadarModel::kEsr, {});
  closed.clear();
  for (size_t i = 0; i < frames.size(); ++i) {
    esr.Push(frames[i], &closed);
    EXPECT_EQ(closed.size(), i + 1 == frames.size() ? 1u : 0u) << i;
  }
  EXPECT_TRUE(closed[0].complete());
  EXPECT_TRUE(closed[0].detections.empty());  // every slot "no target"
  EXPECT_EQ(esr.stats().detections, 0);
}

double Uniform(std::mt19937& rng, double lo, double hi) {
  return std::uniform_real_distribution<double>(lo, hi)(rng);
}

// Random cycles for several sensors and both lists, interleaved in time, through a candump
// file and back.
TEST(RadarDecoderTest, Ars408EncodeWriteReadDecodeRoundTrip) {
  std::mt19937 rng(17);  // fixed seed
  RadarConventions conventions;
  conventions.ars408_object_lat_left_positive = false;  // the non-default sign must survive too
  std::vector<RadarCycle> sent;
  std::vector<CanFrame> frames;
  const CanTime start = CanTime(std::chrono::seconds(1'700'000'000));
  constexpr auto kCyclePeriod = std::chrono::milliseconds(72);  // ARS408 cycle time
  for (int k = 0; k < 40; ++k) {
    RadarCycle c;
    c.sensor_id = k % 3 == 0 ? 0 : (k % 3 == 1 ? 1 : 7);
    c.kind = k % 2 == 0 ? RadarDetectionKind::kCluster : RadarDetectionKind::kObject;
    c.counter = static_cast<uint32_t>(k);
    c.time = start + kCyclePeriod * k;
    const int n = static_cast<int>(Uniform(rng, 0, 60));
    for (int i = 0; i < n; ++i) {
      RadarDetection d;
      d.id = i * 4 + static_cast<int>(Uniform(rng, 0, 3.99));  // distinct ids up to 239
      d.kind = c.kind;
      d.range_m = Uniform(rng, 5, 90);  // |y| stays within the cluster DistLat's ±102.3 m
      d.azimuth_rad = Uniform(rng, -60, 60) * kRadPerDeg;
      d.range_rate_mps = Uniform(rng, -20, 20);
      d.rcs_dbsm = Uniform(rng, -20, 40);
      if (c.kind == RadarDetectionKind::kCluster && i % 2 == 0) {
        d.cluster_quality = Ars408ClusterQuality{i % 32, (i + 5) % 32, i % 8, (i + 1) % 8, i % 3};
      }
      c.detections.push_back(d);
    }
    c.messages_expected = c.messages_received = n;
    absl::StatusOr<std::vector<CanFrame>> encoded = EncodeArs408Cycle(c, "can0", conventions);
    ASSERT_TRUE(encoded.ok()) << encoded.status();
    frames.insert(frames.end(), encoded->begin(), encoded->end());
    sent.push_back(c);
  }
  std::stable_sort(frames.begin(), frames.end(),
                   [](const CanFrame& a, const CanFrame& b) { return a.time < b.time; });
  const testing_support::ScopedPath scratch("ars408", ".log");
  const std::filesystem::path& path = scratch.path();
  ASSERT_TRUE(WriteCandumpLog(path, frames).ok());
  const absl::StatusOr<std::vector<CanFrame>> read = ReadCandumpLog(path);
  ASSERT_TRUE(read.ok()) << read.status();
  const RadarDecodeResult r = DecodeRadarFrames(*read, RadarModel::kArs408, conventions);
  EXPECT_EQ(r.stats.skipped_total(), 0);
  EXPECT_EQ(r.stats.incomplete_cycles, 0);
  ASSERT_EQ(r.cycles.size(), sent.size());
  for (const RadarCycle& got : r.cycles) {
    const RadarCycle& want = sent.at(got.counter);
    EXPECT_EQ(got.time, want.time);
    EXPECT_EQ(got.sensor_id, want.sensor_id);
    EXPECT_EQ(got.kind, want.kind);
    EXPECT_TRUE(got.complete());
    ASSERT_EQ(got.detections.size(), want.detections.size());
    for (size_t i = 0; i < got.detections.size(); ++i) {
      const RadarDetection& g = got.detections[i];
      const RadarDetection& w = want.detections[i];
      EXPECT_EQ(g.id, w.id);
      EXPECT_EQ(g.kind, w.kind);
      // DistLong/DistLat are 0.2 m steps: each axis within 0.1 m, so the point within
      // 0.1·√2 m; that bounds the range and, seen from range r, the azimuth.
      const double position_bound = 0.1 * std::numbers::sqrt2;
      const double azimuth_bound = std::asin(position_bound / w.range_m);
      EXPECT_LE(std::abs(g.x_m() - w.x_m()), 0.1 + kFloatSlack);
      EXPECT_LE(std::abs(g.y_m() - w.y_m()), 0.1 + kFloatSlack);
      EXPECT_LE(std::abs(g.range_m - w.range_m), position_bound + kFloatSlack);
      EXPECT_LE(std::abs(g.azimuth_rad - w.azimuth_rad), azimuth_bound + kFloatSlack);
      // Velocity: 0.25 m/s steps per axis (≤ 0.125·√2 off), seen along a line of sight
      // turned by at most azimuth_bound.
      const double rate_bound =
          0.125 * std::numbers::sqrt2 + std::abs(w.range_rate_mps) * (1 - std::cos(azimuth_bound));
      EXPECT_LE(std::abs(g.range_rate_mps - w.range_rate_mps), rate_bound + kFloatSlack);
      EXPECT_LE(std::abs(*g.rcs_dbsm - *w.rcs_dbsm), 0.25 + kFloatSlack);  // 0.5 dBm² steps
      ASSERT_EQ(g.cluster_quality.has_value(), w.cluster_quality.has_value());
      if (w.cluster_quality) {
        EXPECT_EQ(g.cluster_quality->dist_long_rms, w.cluster_quality->dist_long_rms);
        EXPECT_EQ(g.cluster_quality->invalid_state, w.cluster_quality->invalid_state);
      }
    }
  }
}

TEST(RadarDecoderTest, EsrEncodeWriteReadDecodeRoundTrip) {
  std::mt19937 rng(19);  // fixed seed
  std::vector<RadarCycle> sent;
  std::vector<CanFrame> frames;
  const CanTime start = CanTime(std::chrono::seconds(1'700'000'000));
  constexpr auto kScanPeriod = std::chrono::milliseconds(50);  // ESR scan time
  for (int k = 0; k < 30; ++k) {
    RadarCycle c;
    c.kind = RadarDetectionKind::kTrack;
    c.counter = static_cast<uint32_t>(65530 + k) % 65536;  // the 16-bit scan index wraps
    c.time = start + kScanPeriod * k;
    std::vector<int> ids(64);
    for (int i = 0; i < 64; ++i) ids[i] = i + 1;
    std::shuffle(ids.begin(), ids.end(), rng);
    const int n = static_cast<int>(Uniform(rng, 0, 64.99));
    ids.resize(n);
    std::sort(ids.begin(), ids.end());
    for (int id : ids) {
      RadarDetection d;
      d.kind = RadarDetectionKind::kTrack;
      d.id = id;
      d.range_m = Uniform(rng, 1, 200);
      d.azimuth_rad = Uniform(rng, -50, 50) * kRadPerDeg;
      d.range_rate_mps = Uniform(rng, -80, 80);
      c.detections.push_back(d);
    }
    absl::StatusOr<std::vector<CanFrame>> encoded = EncodeEsrScan(c, "can1", {});
    ASSERT_TRUE(encoded.ok()) << encoded.status();
    frames.insert(frames.end(), encoded->begin(), encoded->end());
    sent.push_back(c);
  }
  const testing_support::ScopedPath scratch("esr", ".log");
  const std::filesystem::path& path = scratch.path();
  ASSERT_TRUE(WriteCandumpLog(path, frames).ok());
  const absl::StatusOr<std::vector<CanFrame>> read = ReadCandumpLog(path);
  ASSERT_TRUE(read.ok()) << read.status();
  const RadarDecodeResult r = DecodeRadarFrames(*read, RadarModel::kEsr, {});
  EXPECT_EQ(r.stats.skipped_total(), 0);
  EXPECT_EQ(r.stats.frames_read, 30 * 65);
  ASSERT_EQ(r.cycles.size(), sent.size());
  for (size_t k = 0; k < sent.size(); ++k) {
    const RadarCycle& got = r.cycles[k];
    EXPECT_EQ(got.counter, sent[k].counter);
    EXPECT_EQ(got.time, sent[k].time);
    EXPECT_TRUE(got.complete());
    ASSERT_EQ(got.detections.size(), sent[k].detections.size());
    for (size_t i = 0; i < got.detections.size(); ++i) {
      const RadarDetection& g = got.detections[i];
      const RadarDetection& w = sent[k].detections[i];
      EXPECT_EQ(g.id, w.id);
      EXPECT_EQ(g.kind, RadarDetectionKind::kTrack);
      // Half a step of 0.1 m, 0.1° and 0.01 m/s.
      EXPECT_LE(std::abs(g.range_m - w.range_m), 0.05 + kFloatSlack);
      EXPECT_LE(std::abs(g.azimuth_rad - w.azimuth_rad), 0.05 * kRadPerDeg + kFloatSlack);
      EXPECT_LE(std::abs(g.range_rate_mps - w.range_rate_mps), 0.005 + kFloatSlack);
      EXPECT_FALSE(g.rcs_dbsm.has_value());
    }
  }
}

TEST(RadarDecoderTest, EsrSkipsFramesOutsideAScan) {
  const std::vector<CanFrame> frames = Parse(
      "(1.0) can0 500#0000000000000000\n"    // before 0x4E0: no_cycle_header
      "(1.1) can0 4E0#0000000100000000\n"    // scan index 31|16: bytes 3-4 = 01 00 = 256
      "(1.2) can0 500#00C0000000000000\n"    // track 1, status 6 (15|3 = byte 1 bits 7..5)
      "(1.3) can0 500#0000000000000000\n"    // track 1 again: duplicate
      "(1.4) can0 53F#00000000\n"            // short
      "(1.5) can0 540#00\n"                  // Track_Sensor: not decoded
      "(1.6) can0 4E1#0000000000000000\n");  // ESR_Status2: not decoded
  const RadarDecodeResult r = DecodeRadarFrames(frames, RadarModel::kEsr, {});
  EXPECT_EQ(Skipped(r.stats, RadarSkipReason::kNoCycleHeader), 1);
  EXPECT_EQ(Skipped(r.stats, RadarSkipReason::kDuplicate), 1);
  EXPECT_EQ(Skipped(r.stats, RadarSkipReason::kShort), 1);
  EXPECT_EQ(Skipped(r.stats, RadarSkipReason::kUnknownId), 2);
  ASSERT_EQ(r.cycles.size(), 1u);
  EXPECT_EQ(r.cycles[0].counter, 256u);
  EXPECT_FALSE(r.cycles[0].complete());
  EXPECT_EQ(r.cycles[0].messages_received, 1);
  ASSERT_EQ(r.cycles[0].detections.size(), 1u);
  EXPECT_EQ(r.cycles[0].detections[0].id, 1);
}

}  // namespace
}  // namespace linecal
