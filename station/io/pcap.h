#pragma once
// pcap files (the classic libpcap format, not pcapng) and the UDP datagrams inside them: how
// LiDAR packets are recorded (captures; the real recordings of docs/external-data.md) and replayed.
//
// Reading accepts microsecond (magic a1b2c3d4) and nanosecond (a1b23c4d) time stamps in
// either byte order; writing produces little-endian files with nanosecond time stamps
// unless told otherwise. Frames are parsed as Ethernet (optionally one 802.1Q VLAN tag),
// Linux "cooked" capture (tcpdump -i any) or raw IPv4, then IPv4 and UDP. Nothing here
// touches a socket (station/ must not): this is bytes in, bytes out.

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"

namespace linecal {

// Link types (the file header's "network" field) that ParseUdpFrame understands.
inline constexpr std::uint32_t kPcapLinkEthernet = 1;
inline constexpr std::uint32_t kPcapLinkRawIp = 101;
inline constexpr std::uint32_t kPcapLinkLinuxSll = 113;
// libpcap's largest snapshot length; a record claiming more is corrupt, not a big packet.
inline constexpr std::uint32_t kPcapMaxRecordBytes = 262144;

struct PcapFileInfo {
  bool nanosecond = true;   // time stamps in ns (else µs)
  bool big_endian = false;  // the file's byte order
  std::uint16_t version_major = 2;
  std::uint16_t version_minor = 4;
  std::uint32_t snaplen = kPcapMaxRecordBytes;
  std::uint32_t link_type = kPcapLinkEthernet;
};

struct PcapRecord {
  std::int64_t time_ns = 0;           // capture time, ns since the epoch
  std::uint32_t original_length = 0;  // bytes on the wire; data may hold fewer (snaplen)
  std::vector<std::uint8_t> data;     // the captured bytes
};

// Reads records one at a time (memory: one record). Movable, not copyable.
class PcapReader {
 public:
  // Opens a file and reads its header. NotFound when it cannot be opened; InvalidArgument
  // "<path>: ..." when it is not a classic pcap file (naming pcapng when it is one) or its
  // version is not 2.x. Cost: one 24-byte read.
  static absl::StatusOr<PcapReader> Open(const std::filesystem::path& path);
  // The same over bytes in memory (tests, fuzzing); `name` stands for the path in messages.
  static absl::StatusOr<PcapReader> FromBytes(std::string bytes, std::string name);

  const PcapFileInfo& info() const { return info_; }

  // Reads the next record into *record. Returns false at the end of the file. A record cut
  // short by the end of the file (a capture that was killed) also ends it, and sets
  // truncated_tail(). DataLoss "<path>: record N: ..." when a record header claims more than
  // kPcapMaxRecordBytes (the file is corrupt from there on). Cost: one read of the record.
  absl::StatusOr<bool> Next(PcapRecord* record);

  bool truncated_tail() const { return truncated_tail_; }
  std::int64_t records_read() const { return records_read_; }

 private:
  PcapReader(std::unique_ptr<std::istream> in, std::string name);
  absl::Status ReadHeader();

  std::unique_ptr<std::istream> in_;
  std::string name_;
  PcapFileInfo info_;
  bool truncated_tail_ = false;
  bool done_ = false;
  std::int64_t records_read_ = 0;
};

// Where a datagram came from and went to. IPv4 addresses in host byte order
// (192.168.1.201 is 0xC0A801C9).
struct UdpEndpoints {
  std::uint32_t src_ip = 0xC0A801C9;  // 192.168.1.201, the LiDARs' factory default address
  std::uint32_t dst_ip = 0xFFFFFFFF;  // broadcast, where they send by default
  std::uint16_t src_port = 2368;
  std::uint16_t dst_port = 2368;
};

// What a captured frame turned out to be.
enum class FrameKind {
  kUdp,          // an IPv4 UDP datagram (possibly with its payload cut short by the capture)
  kOther,        // something else: ARP, IPv6, TCP, ICMP, ...
  kFragment,     // a piece of a fragmented IPv4 datagram (not reassembled)
  kTruncated,    // the capture cut the frame inside its headers
  kMalformed,    // header lengths that contradict each other
  kUnknownLink,  // a link type other than those above
};
inline constexpr int kFrameKindCount = 6;
// "udp", "other", "fragment", "truncated", "malformed", "unknown_link".
const char* FrameKindName(FrameKind kind);

struct UdpFrame {
  FrameKind kind = FrameKind::kMalformed;
  UdpEndpoints endpoints;                 // valid when kind == kUdp
  std::span<const std::uint8_t> payload;  // into the frame; valid when kind == kUdp
  bool payload_truncated = false;         // fewer captured bytes than the UDP length says
};

// Parses one captured frame of `link_type` down to its UDP payload. Never fails on any
// input; the result says what the frame was. Cost: O(1) (no copy).
UdpFrame ParseUdpFrame(std::uint32_t link_type, std::span<const std::uint8_t> frame);

// Builds an Ethernet II + IPv4 + UDP frame around `payload` (IPv4 header checksum set, UDP
// checksum 0 = none, as IPv4 allows). InvalidArgument when the payload does not fit one
// unfragmented datagram (65507 bytes). Cost: O(payload).
absl::StatusOr<std::vector<std::uint8_t>> BuildUdpFrame(const UdpEndpoints& endpoints,
                                                        std::span<const std::uint8_t> payload,
                                                        std::uint16_t ip_id);

struct PcapWriterOptions {
  bool nanosecond = true;
  std::uint32_t link_type = kPcapLinkEthernet;
  std::uint32_t snaplen = kPcapMaxRecordBytes;
};

// Writes a little-endian pcap file. Movable, not copyable; Close() (or destruction, which
// ignores errors) finishes the file.
class PcapWriter {
 public:
  // Creates (replaces) the file and writes its header. Internal naming the path on failure.
  static absl::StatusOr<PcapWriter> Create(const std::filesystem::path& path,
                                           PcapWriterOptions options = {});

  // One record of captured bytes; `original_length` defaults to data.size(). InvalidArgument
  // when data is longer than the snaplen or original_length, or the time is before 1970 or
  // past 2106 (the header's u32 seconds). Internal on a write error.
  absl::Status WriteRecord(std::int64_t time_ns, std::span<const std::uint8_t> data,
                           std::optional<std::uint32_t> original_length = std::nullopt);
  // One Ethernet/IPv4/UDP frame around `payload` (BuildUdpFrame); the file must have link
  // type Ethernet (FailedPrecondition otherwise).
  absl::Status WriteUdp(std::int64_t time_ns, const UdpEndpoints& endpoints,
                        std::span<const std::uint8_t> payload);
  // Flushes and closes; Internal naming the path when the data did not reach the file.
  absl::Status Close();

 private:
  PcapWriter(std::unique_ptr<std::ofstream> out, std::filesystem::path path,
             PcapWriterOptions options);

  std::unique_ptr<std::ofstream> out_;
  std::filesystem::path path_;
  PcapWriterOptions options_;
  std::uint16_t next_ip_id_ = 0;
};

}  // namespace linecal
