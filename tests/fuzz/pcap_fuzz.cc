// Fuzzes the pcap reader and the Ethernet/IPv4/UDP parser: each input is read as a pcap file
// as it is, and XORed over a small valid file (so mutations reach the records). Invariants:
// no crash, every UDP payload inside its record.
#include <cstdint>
#include <string>
#include <vector>

#include "station/io/pcap.h"

namespace {

// A little-endian nanosecond file of three records: UDP, UDP over 802.1Q, ARP-like.
std::string Template() {
  std::string file;
  auto put32 = [&](std::uint32_t v) {
    for (int i = 0; i < 4; ++i) file.push_back(static_cast<char>(v >> (8 * i)));
  };
  put32(0xA1B23C4D);
  put32(2 | (4 << 16));
  put32(0);
  put32(0);
  put32(65535);
  put32(linecal::kPcapLinkEthernet);
  const std::vector<std::uint8_t> payload(40, 0x5A);
  std::vector<std::uint8_t> udp = *linecal::BuildUdpFrame(linecal::UdpEndpoints{}, payload, 1);
  std::vector<std::uint8_t> vlan(udp.begin(), udp.begin() + 12);
  vlan.insert(vlan.end(), {0x81, 0x00, 0x00, 0x07});
  vlan.insert(vlan.end(), udp.begin() + 12, udp.end());
  std::vector<std::uint8_t> arp(udp.begin(), udp.begin() + 14);
  arp[12] = 0x08;
  arp[13] = 0x06;
  for (const auto* frame : {&udp, &vlan, &arp}) {
    put32(1'700'000'000);
    put32(5);
    put32(static_cast<std::uint32_t>(frame->size()));
    put32(static_cast<std::uint32_t>(frame->size()));
    file.append(frame->begin(), frame->end());
  }
  return file;
}

void ReadAll(std::string bytes) {
  absl::StatusOr<linecal::PcapReader> r = linecal::PcapReader::FromBytes(std::move(bytes), "fuzz");
  if (!r.ok()) return;
  linecal::PcapRecord rec;
  while (true) {
    const absl::StatusOr<bool> more = r->Next(&rec);
    if (!more.ok() || !*more) break;
    const linecal::UdpFrame f = linecal::ParseUdpFrame(r->info().link_type, rec.data);
    if (f.kind == linecal::FrameKind::kUdp &&
        (f.payload.data() < rec.data.data() ||
         f.payload.data() + f.payload.size() > rec.data.data() + rec.data.size())) {
      __builtin_trap();
    }
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const std::string kTemplate = Template();
  ReadAll(std::string(reinterpret_cast<const char*>(data), size));
  std::string near_valid = kTemplate;
  for (std::size_t i = 0; i < size; ++i)
    near_valid[i % near_valid.size()] ^= static_cast<char>(data[i]);
  // Inputs longer than the template also grow it: records cut short or appended.
  if (size > near_valid.size())
    near_valid.append(reinterpret_cast<const char*>(data), size - near_valid.size());
  ReadAll(std::move(near_valid));
  return 0;
}
