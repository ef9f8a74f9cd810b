#include "station/io/pcap.h"

#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include "gtest/gtest.h"
#include "station/io/byte_io.h"
#include "tests/support/external_data.h"
#include "tests/support/lidar_recording.h"

namespace linecal {
namespace {

std::string ReadFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

std::filesystem::path TempPath(const std::string& name) {
  return std::filesystem::temp_directory_path() /
         (std::string(::testing::UnitTest::GetInstance()->current_test_info()->name()) + "_" +
          name);
}

// 603 VLP-16 packets (1206-byte payloads, 1248-byte Ethernet frames) from the encoder, as
// bytes of a nanosecond pcap file: the layout of the real recording, made here.
constexpr int kEncodedRecords = 603;
const std::string& EncodedVlp16File() {
  static const std::string bytes = [] {
    const std::filesystem::path path = std::filesystem::temp_directory_path() /
                                       ("pcap_test_vlp16_" + std::to_string(::getpid()) + ".pcap");
    testing_support::EncodedRecording rec =
        testing_support::EncodeRecording(LidarModel::kVlp16, LidarReturnMode::kStrongest, 8.1);
    rec.payloads.resize(kEncodedRecords);
    rec.times_ns.resize(kEncodedRecords);
    EXPECT_TRUE(testing_support::WriteRecordingPcap(rec, path).ok());
    std::string file = ReadFile(path.string());
    std::filesystem::remove(path);
    return file;
  }();
  return bytes;
}

// The real VLP-16 recording (docs/external-data.md): what a sensor sent, not our encoder.
TEST(PcapReader, ReadsTheRecordedVlp16File) {
  LINECAL_EXTERNAL_OR_SKIP(pcap, "lidar/vlp16/packets.pcap");
  absl::StatusOr<PcapReader> r = PcapReader::Open(pcap);
  ASSERT_TRUE(r.ok()) << r.status();
  EXPECT_TRUE(r->info().nanosecond);
  EXPECT_FALSE(r->info().big_endian);
  EXPECT_EQ(r->info().link_type, kPcapLinkEthernet);
  EXPECT_EQ(r->info().version_major, 2);
  EXPECT_EQ(r->info().version_minor, 4);
  PcapRecord rec;
  int n = 0;
  std::int64_t first_time = 0;
  while (true) {
    absl::StatusOr<bool> more = r->Next(&rec);
    ASSERT_TRUE(more.ok()) << more.status();
    if (!*more) break;
    if (n == 0) first_time = rec.time_ns;
    ++n;
    ASSERT_EQ(rec.data.size(), 1248u);  // 42 header bytes + 1206 payload
    ASSERT_EQ(rec.original_length, 1248u);
    const UdpFrame f = ParseUdpFrame(r->info().link_type, rec.data);
    ASSERT_EQ(f.kind, FrameKind::kUdp);
    EXPECT_EQ(f.payload.size(), 1206u);
    EXPECT_FALSE(f.payload_truncated);
    EXPECT_EQ(f.endpoints.src_ip, 0xC0A801C9u);  // 192.168.1.201 (docs/sensors.md)
    EXPECT_EQ(f.endpoints.dst_ip, 0xFFFFFFFFu);
    EXPECT_EQ(f.endpoints.src_port, 2368);
    EXPECT_EQ(f.endpoints.dst_port, 2368);
  }
  EXPECT_EQ(n, 603);
  EXPECT_EQ(r->records_read(), 603);
  EXPECT_FALSE(r->truncated_tail());
  // The first record header: 1673400471 s, 737763166 ns.
  EXPECT_EQ(first_time, 1673400471'737763166);
}

TEST(PcapUdp, BuildsTheSameHeadersAsTheRecording) {
  // The real recording's headers (written afresh, docs/external-data.md) are what
  // BuildUdpFrame writes for IP id 0, checksum included: a byte-exact check of the
  // Ethernet/IPv4/UDP layout against bytes this project did not write.
  LINECAL_EXTERNAL_OR_SKIP(pcap, "lidar/vlp16/packets.pcap");
  absl::StatusOr<PcapReader> r = PcapReader::Open(pcap);
  ASSERT_TRUE(r.ok());
  PcapRecord rec;
  ASSERT_TRUE(*r->Next(&rec));
  const UdpFrame f = ParseUdpFrame(kPcapLinkEthernet, rec.data);
  absl::StatusOr<std::vector<std::uint8_t>> built = BuildUdpFrame(UdpEndpoints{}, f.payload, 0);
  ASSERT_TRUE(built.ok());
  EXPECT_EQ(*built, rec.data);
}

TEST(PcapWriter, RoundTripsMicroAndNanosecondFiles) {
  for (bool nanosecond : {true, false}) {
    const std::filesystem::path path = TempPath(nanosecond ? "ns.pcap" : "us.pcap");
    PcapWriterOptions o;
    o.nanosecond = nanosecond;
    absl::StatusOr<PcapWriter> w = PcapWriter::Create(path, o);
    ASSERT_TRUE(w.ok()) << w.status();
    const std::vector<std::uint8_t> payload = {1, 2, 3, 4, 5};
    UdpEndpoints e;
    e.src_ip = 0x0A000001;
    e.dst_ip = 0x0A000002;
    e.src_port = 1111;
    e.dst_port = 2222;
    ASSERT_TRUE(w->WriteUdp(1'600'000'000'123'456'789, e, payload).ok());
    ASSERT_TRUE(w->WriteRecord(1'600'000'001'000'000'000, payload, 60).ok());
    ASSERT_TRUE(w->Close().ok());

    absl::StatusOr<PcapReader> r = PcapReader::Open(path);
    ASSERT_TRUE(r.ok()) << r.status();
    EXPECT_EQ(r->info().nanosecond, nanosecond);
    PcapRecord rec;
    ASSERT_TRUE(*r->Next(&rec));
    // Microsecond files keep whole microseconds.
    EXPECT_EQ(rec.time_ns, nanosecond ? 1'600'000'000'123'456'789 : 1'600'000'000'123'456'000);
    const UdpFrame f = ParseUdpFrame(r->info().link_type, rec.data);
    ASSERT_EQ(f.kind, FrameKind::kUdp);
    EXPECT_EQ(f.endpoints.src_ip, e.src_ip);
    EXPECT_EQ(f.endpoints.dst_ip, e.dst_ip);
    EXPECT_EQ(f.endpoints.src_port, 1111);
    EXPECT_EQ(f.endpoints.dst_port, 2222);
    EXPECT_EQ(std::vector<std::uint8_t>(f.payload.begin(), f.payload.end()), payload);
    ASSERT_TRUE(*r->Next(&rec));
    EXPECT_EQ(rec.original_length, 60u);
    EXPECT_EQ(rec.data, payload);
    EXPECT_FALSE(*r->Next(&rec));
    EXPECT_FALSE(r->truncated_tail());
    std::filesystem::remove(path);
  }
}

TEST(PcapWriter, RejectsWhatAFileCannotHold) {
  const std::filesystem::path path = TempPath("w.pcap");
  PcapWriterOptions o;
  o.snaplen = 4;
  absl::StatusOr<PcapWriter> w = PcapWriter::Create(path, o);
  ASSERT_TRUE(w.ok());
  const std::vector<std::uint8_t> five(5, 0);
  EXPECT_EQ(w->WriteRecord(0, five).code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(w->WriteRecord(-1, {five.data(), 4}).code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(w->WriteRecord(0, {five.data(), 4}, 3).code(), absl::StatusCode::kInvalidArgument);
  EXPECT_TRUE(w->Close().ok());
  o.link_type = kPcapLinkRawIp;
  w = PcapWriter::Create(path, o);
  ASSERT_TRUE(w.ok());
  EXPECT_EQ(w->WriteUdp(0, UdpEndpoints{}, five).code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_EQ(PcapWriter::Create("/nonexistent/dir/x.pcap").status().code(),
            absl::StatusCode::kInternal);
  std::filesystem::remove(path);
}

// The recording with every header field byte-swapped: a big-endian writer's file.
std::string ToBigEndian(const std::string& little) {
  std::string big = little;
  auto swap32 = [&](std::size_t at) {
    StoreBe32(reinterpret_cast<std::uint8_t*>(&big[at]),
              LoadLe32(reinterpret_cast<const std::uint8_t*>(&little[at])));
  };
  auto swap16 = [&](std::size_t at) {
    StoreBe16(reinterpret_cast<std::uint8_t*>(&big[at]),
              LoadLe16(reinterpret_cast<const std::uint8_t*>(&little[at])));
  };
  swap32(0);
  swap16(4);
  swap16(6);
  swap32(8);
  swap32(12);
  swap32(16);
  swap32(20);
  std::size_t at = 24;
  while (at + 16 <= little.size()) {
    const std::uint32_t captured = LoadLe32(reinterpret_cast<const std::uint8_t*>(&little[at + 8]));
    for (int f = 0; f < 4; ++f) swap32(at + 4 * f);
    at += 16 + captured;
  }
  return big;
}

TEST(PcapReader, ReadsBigEndianFiles) {
  const std::string& little = EncodedVlp16File();
  absl::StatusOr<PcapReader> a = PcapReader::FromBytes(little, "le");
  absl::StatusOr<PcapReader> b = PcapReader::FromBytes(ToBigEndian(little), "be");
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_TRUE(b->info().big_endian);
  EXPECT_TRUE(b->info().nanosecond);
  EXPECT_EQ(b->info().link_type, kPcapLinkEthernet);
  PcapRecord ra, rb;
  int n = 0;
  while (*a->Next(&ra)) {
    ASSERT_TRUE(*b->Next(&rb));
    ASSERT_EQ(ra.time_ns, rb.time_ns);
    ASSERT_EQ(ra.data, rb.data);
    ++n;
  }
  EXPECT_FALSE(*b->Next(&rb));
  EXPECT_EQ(n, kEncodedRecords);
}

TEST(PcapReader, TruncatedFilesEndAtTheLastWholeRecord) {
  const std::string& file = EncodedVlp16File();
  constexpr std::size_t kRecord = 16 + 1248;
  struct Cut {
    std::size_t bytes;
    int whole_records;
    bool truncated;
  };
  for (const Cut& c : {Cut{24, 0, false}, Cut{24 + 7, 0, true}, Cut{24 + 16 + 500, 0, true},
                       Cut{24 + 2 * kRecord, 2, false}, Cut{24 + 2 * kRecord + 15, 2, true},
                       Cut{24 + 3 * kRecord - 1, 2, true}}) {
    absl::StatusOr<PcapReader> r = PcapReader::FromBytes(file.substr(0, c.bytes), "cut");
    ASSERT_TRUE(r.ok()) << r.status();
    PcapRecord rec;
    int n = 0;
    while (true) {
      absl::StatusOr<bool> more = r->Next(&rec);
      ASSERT_TRUE(more.ok()) << more.status();
      if (!*more) break;
      ++n;
    }
    EXPECT_EQ(n, c.whole_records) << c.bytes;
    EXPECT_EQ(r->truncated_tail(), c.truncated) << c.bytes;
    EXPECT_FALSE(*r->Next(&rec));  // stays at the end
  }
}

TEST(PcapReader, RejectsWhatIsNotAPcapFile) {
  const std::string& file = EncodedVlp16File();
  auto code = [](const std::string& bytes) {
    return PcapReader::FromBytes(bytes, "x.pcap").status().code();
  };
  EXPECT_EQ(code(file.substr(0, 23)), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(code("not a pcap file, just some text\n"), absl::StatusCode::kInvalidArgument);
  std::string pcapng = file;
  StoreLe32(reinterpret_cast<std::uint8_t*>(pcapng.data()), 0x0A0D0D0A);
  const absl::Status ng = PcapReader::FromBytes(pcapng, "x.pcapng").status();
  EXPECT_EQ(ng.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(ng.message().find("pcapng"), std::string::npos);
  std::string v3 = file;
  v3[4] = 3;  // version 3.4
  EXPECT_EQ(code(v3), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(PcapReader::Open("/nonexistent.pcap").status().code(), absl::StatusCode::kNotFound);

  // A record that claims 1 GB is corruption, reported with the record number.
  std::string corrupt = file.substr(0, 24 + 2 * (16 + 1248) + 16);
  StoreLe32(reinterpret_cast<std::uint8_t*>(&corrupt[24 + 2 * (16 + 1248) + 8]), 1u << 30);
  absl::StatusOr<PcapReader> r = PcapReader::FromBytes(corrupt, "c.pcap");
  ASSERT_TRUE(r.ok());
  PcapRecord rec;
  EXPECT_TRUE(*r->Next(&rec));
  EXPECT_TRUE(*r->Next(&rec));
  const absl::StatusOr<bool> bad = r->Next(&rec);
  EXPECT_EQ(bad.status().code(), absl::StatusCode::kDataLoss);
  EXPECT_NE(bad.status().message().find("c.pcap: record 3"), std::string::npos);
}

std::vector<std::uint8_t> SampleFrame(std::size_t payload_bytes = 10) {
  return *BuildUdpFrame(UdpEndpoints{}, std::vector<std::uint8_t>(payload_bytes, 0xAB), 9);
}

TEST(PcapUdp, ParsesLinkLayersAndRejectsOtherFrames) {
  const std::vector<std::uint8_t> eth = SampleFrame();
  EXPECT_EQ(ParseUdpFrame(kPcapLinkEthernet, eth).kind, FrameKind::kUdp);

  // 802.1Q: a 4-byte tag before the EtherType.
  std::vector<std::uint8_t> vlan(eth.begin(), eth.begin() + 12);
  for (std::uint8_t b : {0x81, 0x00, 0x00, 0x05}) vlan.push_back(b);
  vlan.insert(vlan.end(), eth.begin() + 12, eth.end());
  UdpFrame f = ParseUdpFrame(kPcapLinkEthernet, vlan);
  EXPECT_EQ(f.kind, FrameKind::kUdp);
  EXPECT_EQ(f.payload.size(), 10u);

  // Linux cooked capture: 16 bytes, protocol in the last two.
  std::vector<std::uint8_t> sll(16, 0);
  sll[14] = 0x08;
  sll.insert(sll.end(), eth.begin() + 14, eth.end());
  EXPECT_EQ(ParseUdpFrame(kPcapLinkLinuxSll, sll).kind, FrameKind::kUdp);
  const std::vector<std::uint8_t> raw(eth.begin() + 14, eth.end());
  f = ParseUdpFrame(kPcapLinkRawIp, raw);
  EXPECT_EQ(f.kind, FrameKind::kUdp);
  EXPECT_EQ(f.payload[0], 0xAB);
  EXPECT_EQ(ParseUdpFrame(147, eth).kind, FrameKind::kUnknownLink);

  std::vector<std::uint8_t> arp = eth;
  arp[12] = 0x08;
  arp[13] = 0x06;
  EXPECT_EQ(ParseUdpFrame(kPcapLinkEthernet, arp).kind, FrameKind::kOther);
  std::vector<std::uint8_t> tcp = eth;
  tcp[14 + 9] = 6;
  EXPECT_EQ(ParseUdpFrame(kPcapLinkEthernet, tcp).kind, FrameKind::kOther);
  std::vector<std::uint8_t> fragment = eth;
  fragment[14 + 6] = 0x20;  // more fragments
  EXPECT_EQ(ParseUdpFrame(kPcapLinkEthernet, fragment).kind, FrameKind::kFragment);
  std::vector<std::uint8_t> bad_ihl = eth;
  bad_ihl[14] = 0x44;
  EXPECT_EQ(ParseUdpFrame(kPcapLinkEthernet, bad_ihl).kind, FrameKind::kMalformed);
  std::vector<std::uint8_t> long_udp = eth;
  long_udp[14 + 20 + 4] = 0x10;  // UDP length beyond the IP datagram
  EXPECT_EQ(ParseUdpFrame(kPcapLinkEthernet, long_udp).kind, FrameKind::kMalformed);

  // Cut by the capture: inside the headers, or inside the payload (still UDP).
  for (std::size_t n : {0, 13, 14 + 19, 14 + 20 + 7}) {
    EXPECT_EQ(ParseUdpFrame(kPcapLinkEthernet, {eth.data(), n}).kind, FrameKind::kTruncated) << n;
  }
  f = ParseUdpFrame(kPcapLinkEthernet, {eth.data(), eth.size() - 3});
  EXPECT_EQ(f.kind, FrameKind::kUdp);
  EXPECT_TRUE(f.payload_truncated);
  EXPECT_EQ(f.payload.size(), 7u);

  EXPECT_EQ(BuildUdpFrame(UdpEndpoints{}, std::vector<std::uint8_t>(65508), 0).status().code(),
            absl::StatusCode::kInvalidArgument);
  EXPECT_STREQ(FrameKindName(FrameKind::kFragment), "fragment");
}

}  // namespace
}  // namespace linecal
