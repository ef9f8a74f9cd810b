#include "station/sensors/lidar/lidar_pcap.h"

#include <utility>
#include <vector>

namespace linecal {
namespace {

absl::Status Deliver(std::vector<LidarScan>& scans, const LidarScanSink& on_scan) {
  for (LidarScan& scan : scans) {
    if (absl::Status s = on_scan(std::move(scan)); !s.ok()) return s;
  }
  scans.clear();
  return absl::OkStatus();
}

}  // namespace

absl::Status DecodeLidarPcap(const std::filesystem::path& path, const LidarPcapOptions& options,
                             LidarDecoder* decoder, const LidarScanSink& on_scan,
                             LidarPcapStats* stats) {
  *stats = LidarPcapStats();
  absl::StatusOr<PcapReader> reader = PcapReader::Open(path);
  if (!reader.ok()) return reader.status();
  const std::uint32_t link_type = reader->info().link_type;
  PcapRecord record;
  std::vector<LidarScan> scans;
  while (true) {
    const absl::StatusOr<bool> more = reader->Next(&record);
    if (!more.ok()) return more.status();
    if (!*more) break;
    ++stats->records;
    const UdpFrame frame = ParseUdpFrame(link_type, record.data);
    ++stats->frames[static_cast<int>(frame.kind)];
    if (frame.kind != FrameKind::kUdp) continue;
    if (options.udp_port && frame.endpoints.dst_port != *options.udp_port) {
      ++stats->other_port;
      continue;
    }
    if (frame.payload_truncated) ++stats->payloads_truncated;
    decoder->AddPacket(frame.payload, record.time_ns, &scans);
    if (absl::Status s = Deliver(scans, on_scan); !s.ok()) return s;
  }
  stats->file_truncated = reader->truncated_tail();
  decoder->Finish(&scans);
  return Deliver(scans, on_scan);
}

}  // namespace linecal
