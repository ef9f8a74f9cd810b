// The UDP LiDAR source on loopback: a sender thread replays a Pandar64 recording made with
// the project's encoder (looped) to 127.0.0.1 while the source acquires rotations into a scratch
// capture directory.
#include "daemon/sources/lidar_udp_source.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include "station/io/pcap.h"
#include "station/sensors/lidar/lidar_decoder.h"
#include "station/sensors/lidar/pcd.h"
#include "tests/daemon/loopback_udp.h"
#include "tests/daemon/scratch_dir.h"
#include "tests/support/lidar_recording.h"

namespace linecal {
namespace {

namespace fs = std::filesystem;
using testing_daemon::FreeUdpPort;
using testing_daemon::LoopingSender;
using testing_daemon::Payload;
using Clock = std::chrono::steady_clock;

// Recordings from the project's encoder: 4.5 turns of the Pandar64 in dual return (600
// packets a turn), and of a VLP-16 for another model's packets.
constexpr std::size_t kPandar64PacketsPerTurn = 600;
std::vector<Payload> EncodedPayloads(LidarModel model) {
  return testing_support::EncodeRecording(model, LidarReturnMode::kDual, 4.5).payloads;
}

struct Record {
  std::int64_t time_ns;
  Payload payload;
};
std::vector<Record> PcapRecords(const fs::path& pcap) {
  std::vector<Record> out;
  absl::StatusOr<PcapReader> r = PcapReader::Open(pcap);
  EXPECT_TRUE(r.ok()) << r.status();
  PcapRecord rec;
  while (r.ok() && *r->Next(&rec)) {
    const UdpFrame f = ParseUdpFrame(r->info().link_type, rec.data);
    EXPECT_EQ(f.kind, FrameKind::kUdp);
    out.push_back({rec.time_ns, Payload(f.payload.begin(), f.payload.end())});
  }
  return out;
}

class LidarUdpSourceTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = testing_daemon::FreshTestDir("lidar_src");
    port_ = FreeUdpPort();
    config_.bind_address = "127.0.0.1";
    config_.port = port_;
    angles_file_ = dir_ / "Pandar64.csv";
    std::ofstream(angles_file_) << testing_support::SyntheticAngleCsv(LidarModel::kPandar64);
  }
  void TearDown() override { fs::remove_all(dir_); }

  AcquireRequest Request(int frames, std::chrono::milliseconds deadline) const {
    AcquireRequest r;
    r.capture_dir = dir_.string();
    r.sensor_dir = "roof_lidar";
    r.frames = frames;
    r.deadline = Clock::now() + deadline;
    return r;
  }

  SensorModel RoofLidar() const {
    SensorModel s;
    s.name = "roof_lidar";
    s.kind = SensorKind::kLidar;
    s.model = "pandar64";
    s.angles_file = angles_file_.string();
    return s;
  }

  fs::path dir_;
  fs::path angles_file_;
  std::uint16_t port_ = 0;
  LidarUdpSourceConfig config_;
};

// The datagrams the source wrote are the file's, in order from some packet on (looped), and
// its PCD scans are what a decoder makes of exactly those datagrams.
TEST_F(LidarUdpSourceTest, AcquiresRotationsThatEqualTheDecodeOfTheReceivedPackets) {
  const std::vector<Payload> file = EncodedPayloads(LidarModel::kPandar64);
  ASSERT_EQ(file.size(), 4 * kPandar64PacketsPerTurn + kPandar64PacketsPerTurn / 2);
  LidarUdpSource source(config_);
  std::vector<std::string> progress;
  AcquireRequest request = Request(2, std::chrono::milliseconds(10000));
  request.progress = [&](const std::string& d) { progress.push_back(d); };
  absl::StatusOr<CaptureSensor> got;
  {
    LoopingSender sender(port_, file);
    got = source.Acquire(RoofLidar(), request);
  }
  ASSERT_TRUE(got.ok()) << got.status();
  EXPECT_EQ(got->name, "roof_lidar");
  EXPECT_EQ(got->kind, SensorKind::kLidar);
  ASSERT_TRUE(got->packets.has_value());
  EXPECT_EQ(got->packets->path, "roof_lidar/packets.pcap");
  ASSERT_EQ(got->frames.size(), 2u);
  EXPECT_EQ(got->frames[0].path, "roof_lidar/scan_0.pcd");
  EXPECT_EQ(got->frames[1].path, "roof_lidar/scan_1.pcd");

  // The pcap: the file's payloads cyclically from the first one received, nothing lost.
  const std::vector<Record> written = PcapRecords(dir_ / "roof_lidar/packets.pcap");
  ASSERT_FALSE(written.empty());
  size_t offset = file.size();
  for (size_t i = 0; i < file.size(); ++i) {
    if (file[i] == written[0].payload) offset = i;
  }
  ASSERT_LT(offset, file.size()) << "the first packet received is not one of the file's";
  for (size_t k = 0; k < written.size(); ++k) {
    ASSERT_EQ(written[k].payload, file[(offset + k) % file.size()]) << "datagram " << k;
  }
  EXPECT_EQ(got->packets->t_ns, written[0].time_ns);
  const LidarUdpCounters counters = source.last_counters();
  EXPECT_EQ(counters.receiver.datagrams, static_cast<std::int64_t>(written.size()));
  EXPECT_EQ(counters.receiver.kernel_drops, 0);
  EXPECT_EQ(counters.decoder.skipped_total(), 0);
  EXPECT_EQ(counters.decoder.scans, 2);
  // Two rotations, after up to one partial rotation, and the few packets past the second
  // that its beams with positive azimuth offsets (up to 2.6 degrees) still fire in.
  EXPECT_GE(written.size(), 2 * kPandar64PacketsPerTurn);
  EXPECT_LE(written.size(), 3 * kPandar64PacketsPerTurn + kPandar64PacketsPerTurn / 20);

  // The scans: a fresh decoder over the same datagrams with the same receive times.
  absl::StatusOr<LidarDecoder> decoder = LidarDecoder::Create(*LidarBeamTableOf(RoofLidar()));
  std::vector<LidarScan> expected;
  for (const Record& r : written) decoder->AddPacket(r.payload, r.time_ns, &expected);
  ASSERT_GE(expected.size(), 2u);
  for (size_t k = 0; k < 2; ++k) {
    absl::StatusOr<PcdCloud> cloud = ReadPcd(dir_ / got->frames[k].path);
    ASSERT_TRUE(cloud.ok()) << cloud.status();
    ASSERT_GT(expected[k].points.size(), 10000u);
    EXPECT_TRUE(cloud->points == expected[k].points) << "scan " << k;
    EXPECT_EQ(got->frames[k].t_ns, expected[k].stamp_ns);
  }
  ASSERT_EQ(progress.size(), 3u);
  EXPECT_EQ(progress[0].rfind("rotation 1/2: datagrams ", 0), 0u) << progress[0];
  EXPECT_NE(progress[2].find("kernel drops 0"), std::string::npos) << progress[2];
}

TEST_F(LidarUdpSourceTest, TruncatedPacketsAreCountedAndSkipped) {
  std::vector<Payload> file = EncodedPayloads(LidarModel::kPandar64);
  // Every 50th packet cut to 600 bytes, as a lossy link would.
  for (size_t i = 0; i < file.size(); i += 50) file[i].resize(600);
  LidarUdpSource source(config_);
  absl::StatusOr<CaptureSensor> got;
  {
    LoopingSender sender(port_, file);
    got = source.Acquire(RoofLidar(), Request(2, std::chrono::milliseconds(10000)));
  }
  ASSERT_TRUE(got.ok()) << got.status();
  const std::vector<Record> written = PcapRecords(dir_ / "roof_lidar/packets.pcap");
  std::int64_t short_packets = 0;
  for (const Record& r : written) short_packets += r.payload.size() == 600;
  const LidarUdpCounters counters = source.last_counters();
  // At least two turns received (1200 consecutive packets of the loop), one in 50 cut.
  EXPECT_GE(short_packets, static_cast<std::int64_t>(2 * kPandar64PacketsPerTurn / 50));
  EXPECT_EQ(counters.decoder.skipped[static_cast<int>(LidarSkipReason::kTruncated)], short_packets);
  EXPECT_EQ(counters.decoder.skipped_total(), short_packets);
  EXPECT_EQ(counters.decoder.packets_decoded,
            static_cast<std::int64_t>(written.size()) - short_packets);
  EXPECT_EQ(got->frames.size(), 2u);
}

TEST_F(LidarUdpSourceTest, SilentPortIsDeadlineExceededAtTheDeadline) {
  LidarUdpSource source(config_);
  const auto start = Clock::now();
  absl::StatusOr<CaptureSensor> got =
      source.Acquire(RoofLidar(), Request(2, std::chrono::milliseconds(2000)));
  const double elapsed = std::chrono::duration<double>(Clock::now() - start).count();
  ASSERT_TRUE(absl::IsDeadlineExceeded(got.status())) << got.status();
  EXPECT_EQ(got.status().message(),
            "roof_lidar: no packets from 127.0.0.1:" + std::to_string(port_) + " in 2.0 s");
  EXPECT_GE(elapsed, 2.0);
  EXPECT_LT(elapsed, 2.5);
}

TEST_F(LidarUdpSourceTest, AnotherModelsPacketsAreDataLossNamingTheCount) {
  LidarUdpSource source(config_);
  absl::StatusOr<CaptureSensor> got;
  {
    LoopingSender sender(port_, EncodedPayloads(LidarModel::kVlp16));
    got = source.Acquire(RoofLidar(), Request(1, std::chrono::milliseconds(1000)));
  }
  ASSERT_TRUE(absl::IsDataLoss(got.status())) << got.status();
  const LidarUdpCounters counters = source.last_counters();
  // How many arrive in the second depends on the machine's load (a sanitized build on two busy
  // cores sends fewer); what matters is that every one of them is counted as skipped.
  EXPECT_GT(counters.receiver.datagrams, 10);
  EXPECT_EQ(counters.decoder.packets_decoded, 0);
  EXPECT_EQ(counters.decoder.skipped_total(), counters.receiver.datagrams);
  EXPECT_NE(got.status().message().find(absl::StrCat("roof_lidar: ", counters.receiver.datagrams,
                                                     " packets from 127.0.0.1:")),
            std::string::npos)
      << got.status();
  EXPECT_NE(got.status().message().find("none decodes as pandar64"), std::string::npos)
      << got.status();
}

TEST_F(LidarUdpSourceTest, CancelStopsWithinAPollInterval) {
  LidarUdpSource source(config_);
  std::atomic<bool> cancel{false};
  AcquireRequest request = Request(2, std::chrono::milliseconds(10000));
  request.cancel = &cancel;
  std::thread canceller([&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
    cancel = true;
  });
  const auto start = Clock::now();
  absl::StatusOr<CaptureSensor> got = source.Acquire(RoofLidar(), request);
  const double elapsed = std::chrono::duration<double>(Clock::now() - start).count();
  canceller.join();
  EXPECT_TRUE(absl::IsCancelled(got.status())) << got.status();
  EXPECT_LT(elapsed, 0.4);
}

TEST_F(LidarUdpSourceTest, OtherKindsAndBusyPortsAreRefused) {
  LidarUdpSource source(config_);
  SensorModel radar = RoofLidar();
  radar.kind = SensorKind::kRadar;
  EXPECT_TRUE(absl::IsInvalidArgument(
      source.Acquire(radar, Request(1, std::chrono::milliseconds(100))).status()));
  // The port is taken by another receiver: Unavailable naming the address.
  UdpReceiverOptions o;
  o.bind_address = "127.0.0.1";
  o.port = port_;
  absl::StatusOr<std::unique_ptr<UdpReceiver>> other = UdpReceiver::Open(o);
  ASSERT_TRUE(other.ok());
  absl::StatusOr<CaptureSensor> got =
      source.Acquire(RoofLidar(), Request(1, std::chrono::milliseconds(100)));
  EXPECT_TRUE(absl::IsUnavailable(got.status())) << got.status();
  EXPECT_NE(got.status().message().find("127.0.0.1"), std::string::npos) << got.status();
  EXPECT_EQ(source.Describe(), "udp 127.0.0.1:" + std::to_string(port_));
}

}  // namespace
}  // namespace linecal
