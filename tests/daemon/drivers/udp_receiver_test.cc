#include "daemon/drivers/udp_receiver.h"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <filesystem>
#include <string>
#include <thread>
#include <vector>

#include "gtest/gtest.h"
#include "station/io/pcap.h"
#include "station/sensors/lidar/lidar_decoder.h"
#include "station/sensors/lidar/lidar_pcap.h"
#include "tests/support/lidar_recording.h"

namespace linecal {
namespace {

// A recording from the project's encoder, as a pcap file in the temporary folder (the
// receiver is under test here; the decode of real recordings is lidar_decoder_test's).
std::string EncodedPcap(LidarModel model, double turns) {
  const std::string path = (std::filesystem::temp_directory_path() /
                            ("udp_receiver_" + std::string(GetLidarModelInfo(model).name) + "_" +
                             std::to_string(getpid()) + ".pcap"))
                               .string();
  const testing_support::EncodedRecording rec =
      testing_support::EncodeRecording(model, LidarReturnMode::kDual, turns);
  EXPECT_TRUE(testing_support::WriteRecordingPcap(rec, path).ok());
  return path;
}

// A UDP socket that sends to 127.0.0.1:port (loopback only).
class LoopbackSender {
 public:
  explicit LoopbackSender(std::uint16_t port) : fd_(socket(AF_INET, SOCK_DGRAM, 0)) {
    to_.sin_family = AF_INET;
    to_.sin_port = htons(port);
    to_.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  }
  ~LoopbackSender() { close(fd_); }
  bool Send(std::span<const std::uint8_t> bytes) const {
    return sendto(fd_, bytes.data(), bytes.size(), 0, reinterpret_cast<const sockaddr*>(&to_),
                  sizeof(to_)) == static_cast<ssize_t>(bytes.size());
  }

 private:
  int fd_;
  sockaddr_in to_{};
};

UdpReceiverOptions LoopbackOptions() {
  UdpReceiverOptions o;
  o.bind_address = "127.0.0.1";
  o.port = 0;  // any free port
  o.receive_timeout = std::chrono::milliseconds(50);
  return o;
}

std::vector<std::vector<std::uint8_t>> Payloads(const std::string& pcap) {
  std::vector<std::vector<std::uint8_t>> out;
  absl::StatusOr<PcapReader> r = PcapReader::Open(pcap);
  EXPECT_TRUE(r.ok());
  PcapRecord rec;
  while (*r->Next(&rec)) {
    const UdpFrame f = ParseUdpFrame(r->info().link_type, rec.data);
    out.emplace_back(f.payload.begin(), f.payload.end());
  }
  return out;
}

std::vector<LidarScan> DecodeFile(const std::string& pcap, const LidarBeamTable& table) {
  absl::StatusOr<LidarDecoder> decoder = LidarDecoder::Create(table);
  std::vector<LidarScan> scans;
  LidarPcapStats stats;
  EXPECT_TRUE(DecodeLidarPcap(
                  pcap, {}, &*decoder,
                  [&](LidarScan&& s) {
                    scans.push_back(std::move(s));
                    return absl::OkStatus();
                  },
                  &stats)
                  .ok());
  return scans;
}

// Replays the recording's payloads to a receiver on 127.0.0.1 that feeds a decoder, as the
// daemon does. The sender keeps at most kWindow datagrams in flight, so the test does not
// depend on the kernel's receive buffer size.
std::vector<LidarScan> DecodeOverLoopback(const std::string& pcap, const LidarBeamTable& table,
                                          UdpReceiverStats* stats) {
  absl::StatusOr<std::unique_ptr<UdpReceiver>> receiver = UdpReceiver::Open(LoopbackOptions());
  EXPECT_TRUE(receiver.ok()) << receiver.status();
  absl::StatusOr<LidarDecoder> decoder = LidarDecoder::Create(table);
  std::vector<LidarScan> scans;
  std::atomic<int> received{0};
  absl::Status run_status;
  std::thread thread([&] {
    run_status = (*receiver)->Run([&](std::span<const std::uint8_t> payload, std::int64_t t) {
      decoder->AddPacket(payload, t, &scans);
      received.fetch_add(1);
    });
  });
  const std::vector<std::vector<std::uint8_t>> payloads = Payloads(pcap);
  LoopbackSender sender((*receiver)->port());
  constexpr int kWindow = 64;
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(30);
  for (std::size_t i = 0; i < payloads.size(); ++i) {
    while (static_cast<int>(i) - received.load() >= kWindow &&
           std::chrono::steady_clock::now() < deadline) {
      std::this_thread::sleep_for(std::chrono::microseconds(50));
    }
    EXPECT_TRUE(sender.Send(payloads[i]));
  }
  while (received.load() < static_cast<int>(payloads.size()) &&
         std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  (*receiver)->Stop();
  thread.join();
  EXPECT_TRUE(run_status.ok()) << run_status;
  decoder->Finish(&scans);
  *stats = (*receiver)->stats();
  EXPECT_EQ(stats->datagrams, static_cast<std::int64_t>(payloads.size()));
  return scans;
}

TEST(UdpReceiver, LoopbackReplayOfPandar64GivesTheFileDecode) {
  const LidarBeamTable table = testing_support::SyntheticBeamTable(LidarModel::kPandar64);
  // 4.5 turns of dual-return packets: 600 a turn, rotations 1-3 complete.
  const std::string pcap = EncodedPcap(LidarModel::kPandar64, 4.5);
  const std::vector<LidarScan> from_file = DecodeFile(pcap, table);
  UdpReceiverStats stats;
  const std::vector<LidarScan> live = DecodeOverLoopback(pcap, table, &stats);
  std::filesystem::remove(pcap);
  EXPECT_EQ(stats.truncated, 0);
  EXPECT_EQ(stats.kernel_drops, 0);
  EXPECT_EQ(stats.bytes, 2700 * 1198);
  ASSERT_EQ(from_file.size(), 3u);
  ASSERT_EQ(live.size(), from_file.size());
  // Hesai packets carry their own UTC date: identical, times included.
  for (std::size_t i = 0; i < live.size(); ++i) {
    EXPECT_EQ(live[i].rotation, from_file[i].rotation);
    EXPECT_EQ(live[i].stamp_ns, from_file[i].stamp_ns);
    EXPECT_TRUE(live[i].points == from_file[i].points) << "scan " << i;
  }
}

TEST(UdpReceiver, LoopbackReplayOfVlp16GivesTheFileDecode) {
  const LidarBeamTable table = *DefaultBeamTable(LidarModel::kVlp16);
  const std::string pcap = EncodedPcap(LidarModel::kVlp16, 4.5);
  const std::vector<LidarScan> from_file = DecodeFile(pcap, table);
  UdpReceiverStats stats;
  const std::vector<LidarScan> live = DecodeOverLoopback(pcap, table, &stats);
  std::filesystem::remove(pcap);
  EXPECT_EQ(stats.kernel_drops, 0);
  ASSERT_EQ(from_file.size(), 3u);
  ASSERT_EQ(live.size(), from_file.size());
  // VLP-16 times count within the hour, which comes from the receive clock (today, not the
  // recording's day): equal modulo an hour.
  for (std::size_t i = 0; i < live.size(); ++i) {
    ASSERT_EQ(live[i].points.size(), from_file[i].points.size());
    for (std::size_t k = 0; k < live[i].points.size(); ++k) {
      LidarPoint a = live[i].points[k], b = from_file[i].points[k];
      ASSERT_EQ((a.time_ns - b.time_ns) % vlp16::kTimestampPeriodNs, 0) << k;
      a.time_ns = b.time_ns = 0;
      ASSERT_EQ(a, b) << "scan " << i << " point " << k;
    }
  }
}

TEST(UdpReceiver, CountsTimeoutsAndTooLongDatagrams) {
  UdpReceiverOptions o = LoopbackOptions();
  o.max_datagram_bytes = 1206;
  absl::StatusOr<std::unique_ptr<UdpReceiver>> r = UdpReceiver::Open(o);
  ASSERT_TRUE(r.ok()) << r.status();
  int delivered = 0;
  const UdpReceiver::Sink sink = [&](std::span<const std::uint8_t>, std::int64_t) { ++delivered; };
  EXPECT_EQ((*r)->ReceiveOne(sink).code(), absl::StatusCode::kDeadlineExceeded);
  LoopbackSender sender((*r)->port());
  ASSERT_TRUE(sender.Send(std::vector<std::uint8_t>(1207, 1)));
  ASSERT_TRUE(sender.Send(std::vector<std::uint8_t>(1206, 2)));
  EXPECT_TRUE((*r)->ReceiveOne(sink).ok());
  EXPECT_TRUE((*r)->ReceiveOne(sink).ok());
  const UdpReceiverStats s = (*r)->stats();
  EXPECT_EQ(s.timeouts, 1);
  EXPECT_EQ(s.truncated, 1);
  EXPECT_EQ(s.datagrams, 1);
  EXPECT_EQ(s.bytes, 1206);
  EXPECT_EQ(delivered, 1);
  EXPECT_GT((*r)->receive_buffer_bytes(), 0);
}

TEST(UdpReceiver, StopEndsRunPromptly) {
  UdpReceiverOptions o = LoopbackOptions();
  o.receive_timeout = std::chrono::milliseconds(10'000);  // Stop must not wait for this
  absl::StatusOr<std::unique_ptr<UdpReceiver>> r = UdpReceiver::Open(o);
  ASSERT_TRUE(r.ok());
  absl::Status result = absl::UnknownError("not run");
  std::thread t([&] { result = (*r)->Run([](std::span<const std::uint8_t>, std::int64_t) {}); });
  std::this_thread::sleep_for(std::chrono::milliseconds(50));
  const auto before = std::chrono::steady_clock::now();
  (*r)->Stop();
  t.join();
  EXPECT_LT(std::chrono::steady_clock::now() - before, std::chrono::seconds(1));
  EXPECT_TRUE(result.ok()) << result;
  EXPECT_EQ((*r)->ReceiveOne([](std::span<const std::uint8_t>, std::int64_t) {}).code(),
            absl::StatusCode::kCancelled);
}

TEST(UdpReceiver, ReportsBadOptionsAndBusyPorts) {
  UdpReceiverOptions o = LoopbackOptions();
  o.bind_address = "localhost";
  EXPECT_EQ(UdpReceiver::Open(o).status().code(), absl::StatusCode::kInvalidArgument);
  o = LoopbackOptions();
  o.multicast_group = "10.0.0.1";
  const absl::Status not_multicast = UdpReceiver::Open(o).status();
  EXPECT_EQ(not_multicast.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(not_multicast.message().find("multicast_group"), std::string::npos);
  o = LoopbackOptions();
  o.max_datagram_bytes = 0;
  EXPECT_EQ(UdpReceiver::Open(o).status().code(), absl::StatusCode::kInvalidArgument);
  o = LoopbackOptions();
  o.receive_timeout = std::chrono::milliseconds(0);
  EXPECT_EQ(UdpReceiver::Open(o).status().code(), absl::StatusCode::kInvalidArgument);

  absl::StatusOr<std::unique_ptr<UdpReceiver>> first = UdpReceiver::Open(LoopbackOptions());
  ASSERT_TRUE(first.ok());
  o = LoopbackOptions();
  o.port = (*first)->port();
  const absl::Status busy = UdpReceiver::Open(o).status();
  EXPECT_EQ(busy.code(), absl::StatusCode::kUnavailable);
  EXPECT_NE(busy.message().find("127.0.0.1:" + std::to_string(o.port)), std::string::npos) << busy;
  // An address this host does not have.
  o = LoopbackOptions();
  o.bind_address = "192.0.2.1";
  EXPECT_EQ(UdpReceiver::Open(o).status().code(), absl::StatusCode::kUnavailable);
}

}  // namespace
}  // namespace linecal
