#include "station/io/pcap.h"

#include <array>
#include <sstream>
#include <utility>

#include "absl/strings/str_cat.h"
#include "station/io/byte_io.h"

namespace linecal {
namespace {

// File header magics as a little-endian reader sees them.
constexpr std::uint32_t kMagicMicros = 0xA1B2C3D4;
constexpr std::uint32_t kMagicNanos = 0xA1B23C4D;
constexpr std::uint32_t kMagicMicrosSwapped = 0xD4C3B2A1;
constexpr std::uint32_t kMagicNanosSwapped = 0x4D3CB2A1;
// pcapng files open with a Section Header Block of type 0x0A0D0D0A.
constexpr std::uint32_t kPcapngMagic = 0x0A0D0D0A;
constexpr std::size_t kFileHeaderBytes = 24;
constexpr std::size_t kRecordHeaderBytes = 16;
// The file header's link type is the low 16 bits of its last field (the upper bits may
// hold the FCS length).
constexpr std::uint32_t kLinkTypeMask = 0xFFFF;

constexpr std::int64_t kNsPerSecond = 1'000'000'000;
constexpr std::int64_t kNsPerUs = 1000;

// Ethernet II: 6 + 6 bytes of addresses, then the EtherType; 802.1Q inserts 4 bytes.
constexpr std::size_t kEthernetHeaderBytes = 14;
constexpr std::size_t kVlanTagBytes = 4;
// Linux cooked capture (SLL): 16 bytes, protocol type in the last two.
constexpr std::size_t kSllHeaderBytes = 16;
constexpr std::uint16_t kEtherTypeIpv4 = 0x0800;
constexpr std::uint16_t kEtherTypeVlan = 0x8100;
constexpr std::size_t kIpv4MinHeaderBytes = 20;
constexpr std::uint8_t kIpProtocolUdp = 17;
constexpr std::size_t kUdpHeaderBytes = 8;
// An IPv4 datagram is at most 65535 bytes including its 20-byte header and UDP's 8.
constexpr std::size_t kMaxUdpPayloadBytes = 65535 - kIpv4MinHeaderBytes - kUdpHeaderBytes;

std::uint32_t Load32(const std::uint8_t* p, bool big_endian) {
  return big_endian ? LoadBe32(p) : LoadLe32(p);
}
std::uint16_t Load16(const std::uint8_t* p, bool big_endian) {
  return big_endian ? LoadBe16(p) : LoadLe16(p);
}

std::uint16_t Ipv4Checksum(std::span<const std::uint8_t> header) {
  std::uint32_t sum = 0;
  for (std::size_t i = 0; i + 1 < header.size(); i += 2) sum += LoadBe16(header.data() + i);
  while (sum >> 16) sum = (sum & 0xFFFF) + (sum >> 16);
  return static_cast<std::uint16_t>(~sum);
}

}  // namespace

const char* FrameKindName(FrameKind kind) {
  switch (kind) {
    case FrameKind::kUdp:
      return "udp";
    case FrameKind::kOther:
      return "other";
    case FrameKind::kFragment:
      return "fragment";
    case FrameKind::kTruncated:
      return "truncated";
    case FrameKind::kMalformed:
      return "malformed";
    case FrameKind::kUnknownLink:
      return "unknown_link";
  }
  return "unknown";
}

PcapReader::PcapReader(std::unique_ptr<std::istream> in, std::string name)
    : in_(std::move(in)), name_(std::move(name)) {}

absl::StatusOr<PcapReader> PcapReader::Open(const std::filesystem::path& path) {
  auto in = std::make_unique<std::ifstream>(path, std::ios::binary);
  if (!*in) return absl::NotFoundError(absl::StrCat("cannot open ", path.string()));
  PcapReader reader(std::move(in), path.string());
  if (absl::Status s = reader.ReadHeader(); !s.ok()) return s;
  return reader;
}

absl::StatusOr<PcapReader> PcapReader::FromBytes(std::string bytes, std::string name) {
  PcapReader reader(std::make_unique<std::istringstream>(std::move(bytes)), std::move(name));
  if (absl::Status s = reader.ReadHeader(); !s.ok()) return s;
  return reader;
}

absl::Status PcapReader::ReadHeader() {
  std::array<std::uint8_t, kFileHeaderBytes> h{};
  in_->read(reinterpret_cast<char*>(h.data()), h.size());
  const std::size_t got = static_cast<std::size_t>(in_->gcount());
  if (got >= 4 && LoadLe32(h.data()) == kPcapngMagic) {
    return absl::InvalidArgumentError(
        absl::StrCat(name_, ": a pcapng file; convert it to pcap (editcap -F pcap IN OUT)"));
  }
  if (got < kFileHeaderBytes) {
    return absl::InvalidArgumentError(
        absl::StrCat(name_, ": not a pcap file (", got, " bytes, shorter than its header)"));
  }
  const std::uint32_t magic = LoadLe32(h.data());
  switch (magic) {
    case kMagicMicros:
      info_.nanosecond = false;
      info_.big_endian = false;
      break;
    case kMagicNanos:
      info_.nanosecond = true;
      info_.big_endian = false;
      break;
    case kMagicMicrosSwapped:
      info_.nanosecond = false;
      info_.big_endian = true;
      break;
    case kMagicNanosSwapped:
      info_.nanosecond = true;
      info_.big_endian = true;
      break;
    default:
      return absl::InvalidArgumentError(
          absl::StrCat(name_, ": not a pcap file (magic 0x", absl::Hex(magic), ")"));
  }
  const bool be = info_.big_endian;
  info_.version_major = Load16(h.data() + 4, be);
  info_.version_minor = Load16(h.data() + 6, be);
  info_.snaplen = Load32(h.data() + 16, be);
  info_.link_type = Load32(h.data() + 20, be) & kLinkTypeMask;
  if (info_.version_major != 2) {
    return absl::InvalidArgumentError(absl::StrCat(name_, ": pcap version ", info_.version_major,
                                                   ".", info_.version_minor, " (expected 2.x)"));
  }
  return absl::OkStatus();
}

absl::StatusOr<bool> PcapReader::Next(PcapRecord* record) {
  if (done_) return false;
  std::array<std::uint8_t, kRecordHeaderBytes> h{};
  in_->read(reinterpret_cast<char*>(h.data()), h.size());
  const std::size_t got = static_cast<std::size_t>(in_->gcount());
  if (got == 0) {
    done_ = true;
    return false;
  }
  if (got < kRecordHeaderBytes) {
    done_ = true;
    truncated_tail_ = true;
    return false;
  }
  const bool be = info_.big_endian;
  const std::uint32_t seconds = Load32(h.data(), be);
  const std::uint32_t fraction = Load32(h.data() + 4, be);
  const std::uint32_t captured = Load32(h.data() + 8, be);
  const std::uint32_t original = Load32(h.data() + 12, be);
  if (captured > kPcapMaxRecordBytes) {
    done_ = true;
    return absl::DataLossError(absl::StrCat(name_, ": record ", records_read_ + 1,
                                            ": captured length ", captured, " exceeds ",
                                            kPcapMaxRecordBytes, " (corrupt file)"));
  }
  record->data.resize(captured);
  in_->read(reinterpret_cast<char*>(record->data.data()), captured);
  if (static_cast<std::uint32_t>(in_->gcount()) < captured) {
    done_ = true;
    truncated_tail_ = true;
    return false;
  }
  record->time_ns = static_cast<std::int64_t>(seconds) * kNsPerSecond +
                    static_cast<std::int64_t>(fraction) * (info_.nanosecond ? 1 : kNsPerUs);
  record->original_length = original;
  ++records_read_;
  return true;
}

UdpFrame ParseUdpFrame(std::uint32_t link_type, std::span<const std::uint8_t> frame) {
  UdpFrame out;
  std::size_t ip_at = 0;
  const std::uint8_t* d = frame.data();
  const std::size_t n = frame.size();
  switch (link_type) {
    case kPcapLinkEthernet: {
      if (n < kEthernetHeaderBytes) {
        out.kind = FrameKind::kTruncated;
        return out;
      }
      std::uint16_t ether_type = LoadBe16(d + 12);
      ip_at = kEthernetHeaderBytes;
      if (ether_type == kEtherTypeVlan) {
        if (n < kEthernetHeaderBytes + kVlanTagBytes) {
          out.kind = FrameKind::kTruncated;
          return out;
        }
        ether_type = LoadBe16(d + 16);
        ip_at += kVlanTagBytes;
      }
      if (ether_type != kEtherTypeIpv4) {
        out.kind = FrameKind::kOther;
        return out;
      }
      break;
    }
    case kPcapLinkLinuxSll:
      if (n < kSllHeaderBytes) {
        out.kind = FrameKind::kTruncated;
        return out;
      }
      if (LoadBe16(d + 14) != kEtherTypeIpv4) {
        out.kind = FrameKind::kOther;
        return out;
      }
      ip_at = kSllHeaderBytes;
      break;
    case kPcapLinkRawIp:
      ip_at = 0;
      break;
    default:
      out.kind = FrameKind::kUnknownLink;
      return out;
  }

  if (n < ip_at + kIpv4MinHeaderBytes) {
    out.kind = n > ip_at && (d[ip_at] >> 4) != 4 ? FrameKind::kOther : FrameKind::kTruncated;
    return out;
  }
  const std::uint8_t* ip = d + ip_at;
  if ((ip[0] >> 4) != 4) {
    out.kind = FrameKind::kOther;
    return out;
  }
  const std::size_t ip_header = static_cast<std::size_t>(ip[0] & 0x0F) * 4;
  const std::size_t ip_total = LoadBe16(ip + 2);
  if (ip_header < kIpv4MinHeaderBytes || ip_total < ip_header) {
    out.kind = FrameKind::kMalformed;
    return out;
  }
  if (ip[9] != kIpProtocolUdp) {
    out.kind = FrameKind::kOther;
    return out;
  }
  // More-fragments flag or a non-zero fragment offset: one piece of a larger datagram.
  if ((LoadBe16(ip + 6) & 0x3FFF) != 0) {
    out.kind = FrameKind::kFragment;
    return out;
  }
  const std::size_t udp_at = ip_at + ip_header;
  if (n < udp_at + kUdpHeaderBytes) {
    out.kind = FrameKind::kTruncated;
    return out;
  }
  const std::uint8_t* udp = d + udp_at;
  const std::size_t udp_length = LoadBe16(udp + 4);
  if (udp_length < kUdpHeaderBytes || udp_length > ip_total - ip_header) {
    out.kind = FrameKind::kMalformed;
    return out;
  }
  const std::size_t payload_length = udp_length - kUdpHeaderBytes;
  const std::size_t captured_payload = std::min(payload_length, n - udp_at - kUdpHeaderBytes);
  out.kind = FrameKind::kUdp;
  out.endpoints.src_ip = LoadBe32(ip + 12);
  out.endpoints.dst_ip = LoadBe32(ip + 16);
  out.endpoints.src_port = LoadBe16(udp);
  out.endpoints.dst_port = LoadBe16(udp + 2);
  out.payload = frame.subspan(udp_at + kUdpHeaderBytes, captured_payload);
  out.payload_truncated = captured_payload < payload_length;
  return out;
}

absl::StatusOr<std::vector<std::uint8_t>> BuildUdpFrame(const UdpEndpoints& endpoints,
                                                        std::span<const std::uint8_t> payload,
                                                        std::uint16_t ip_id) {
  if (payload.size() > kMaxUdpPayloadBytes) {
    return absl::InvalidArgumentError(
        absl::StrCat("UDP payload of ", payload.size(), " bytes exceeds ", kMaxUdpPayloadBytes));
  }
  std::vector<std::uint8_t> f(kEthernetHeaderBytes + kIpv4MinHeaderBytes + kUdpHeaderBytes +
                              payload.size());
  std::uint8_t* d = f.data();
  // Destination MAC: broadcast; source MAC: a locally administered address (bit 1 of the
  // first byte set), since the frame is synthetic.
  for (int i = 0; i < 6; ++i) d[i] = 0xFF;
  constexpr std::array<std::uint8_t, 6> kSourceMac = {0x02, 0x00, 0x00, 0x00, 0x00, 0x01};
  for (int i = 0; i < 6; ++i) d[6 + i] = kSourceMac[i];
  StoreBe16(d + 12, kEtherTypeIpv4);
  std::uint8_t* ip = d + kEthernetHeaderBytes;
  ip[0] = 0x45;  // IPv4, 5 × 4-byte header
  StoreBe16(ip + 2,
            static_cast<std::uint16_t>(kIpv4MinHeaderBytes + kUdpHeaderBytes + payload.size()));
  StoreBe16(ip + 4, ip_id);
  StoreBe16(ip + 6, 0x4000);  // don't fragment
  ip[8] = 64;                 // the usual Linux TTL
  ip[9] = kIpProtocolUdp;
  StoreBe32(ip + 12, endpoints.src_ip);
  StoreBe32(ip + 16, endpoints.dst_ip);
  StoreBe16(ip + 10, Ipv4Checksum({ip, kIpv4MinHeaderBytes}));
  std::uint8_t* udp = ip + kIpv4MinHeaderBytes;
  StoreBe16(udp, endpoints.src_port);
  StoreBe16(udp + 2, endpoints.dst_port);
  StoreBe16(udp + 4, static_cast<std::uint16_t>(kUdpHeaderBytes + payload.size()));
  std::copy(payload.begin(), payload.end(), udp + kUdpHeaderBytes);
  return f;
}

PcapWriter::PcapWriter(std::unique_ptr<std::ofstream> out, std::filesystem::path path,
                       PcapWriterOptions options)
    : out_(std::move(out)), path_(std::move(path)), options_(options) {}

absl::StatusOr<PcapWriter> PcapWriter::Create(const std::filesystem::path& path,
                                              PcapWriterOptions options) {
  auto out = std::make_unique<std::ofstream>(path, std::ios::binary | std::ios::trunc);
  if (!*out) return absl::InternalError(absl::StrCat("cannot create ", path.string()));
  std::array<std::uint8_t, kFileHeaderBytes> h{};
  StoreLe32(h.data(), options.nanosecond ? kMagicNanos : kMagicMicros);
  StoreLe16(h.data() + 4, 2);
  StoreLe16(h.data() + 6, 4);
  StoreLe32(h.data() + 16, options.snaplen);
  StoreLe32(h.data() + 20, options.link_type);
  out->write(reinterpret_cast<const char*>(h.data()), h.size());
  if (!*out) return absl::InternalError(absl::StrCat("cannot write ", path.string()));
  return PcapWriter(std::move(out), path, options);
}

absl::Status PcapWriter::WriteRecord(std::int64_t time_ns, std::span<const std::uint8_t> data,
                                     std::optional<std::uint32_t> original_length) {
  if (!out_) return absl::FailedPreconditionError(absl::StrCat(path_.string(), ": closed"));
  const std::uint32_t original = original_length.value_or(static_cast<std::uint32_t>(data.size()));
  if (data.size() > options_.snaplen || data.size() > original) {
    return absl::InvalidArgumentError(
        absl::StrCat("record of ", data.size(), " bytes: longer than the snaplen ",
                     options_.snaplen, " or its original length ", original));
  }
  // The header stores u32 seconds: 1970 .. early 2106.
  constexpr std::int64_t kLastSecond = 0xFFFFFFFFLL;
  const std::int64_t seconds = time_ns / kNsPerSecond;
  if (time_ns < 0 || seconds > kLastSecond) {
    return absl::InvalidArgumentError(
        absl::StrCat("time ", time_ns, " ns is outside what a pcap record can hold"));
  }
  const std::int64_t sub_ns = time_ns - seconds * kNsPerSecond;
  std::array<std::uint8_t, kRecordHeaderBytes> h{};
  StoreLe32(h.data(), static_cast<std::uint32_t>(seconds));
  StoreLe32(h.data() + 4,
            static_cast<std::uint32_t>(options_.nanosecond ? sub_ns : sub_ns / kNsPerUs));
  StoreLe32(h.data() + 8, static_cast<std::uint32_t>(data.size()));
  StoreLe32(h.data() + 12, original);
  out_->write(reinterpret_cast<const char*>(h.data()), h.size());
  out_->write(reinterpret_cast<const char*>(data.data()),
              static_cast<std::streamsize>(data.size()));
  if (!*out_) return absl::InternalError(absl::StrCat("cannot write ", path_.string()));
  return absl::OkStatus();
}

absl::Status PcapWriter::WriteUdp(std::int64_t time_ns, const UdpEndpoints& endpoints,
                                  std::span<const std::uint8_t> payload) {
  if (options_.link_type != kPcapLinkEthernet) {
    return absl::FailedPreconditionError(
        absl::StrCat(path_.string(), ": UDP frames need link type Ethernet"));
  }
  absl::StatusOr<std::vector<std::uint8_t>> frame = BuildUdpFrame(endpoints, payload, next_ip_id_);
  if (!frame.ok()) return frame.status();
  ++next_ip_id_;
  return WriteRecord(time_ns, *frame);
}

absl::Status PcapWriter::Close() {
  if (!out_) return absl::OkStatus();
  out_->flush();
  const bool ok = static_cast<bool>(*out_);
  out_->close();
  out_.reset();
  if (!ok) return absl::InternalError(absl::StrCat("cannot write ", path_.string()));
  return absl::OkStatus();
}

}  // namespace linecal
