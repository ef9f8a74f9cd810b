#pragma once
// Recorded LiDAR packets (pcap files) into a LidarDecoder: the offline path shared by
// `linecal lidar decode`, capture replay and the tests.

#include <array>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <optional>

#include "absl/status/status.h"
#include "station/io/pcap.h"
#include "station/sensors/lidar/lidar_decoder.h"
#include "station/sensors/lidar/lidar_point.h"

namespace linecal {

struct LidarPcapOptions {
  // Only UDP datagrams to this destination port; every UDP datagram when unset.
  std::optional<std::uint16_t> udp_port;
};

struct LidarPcapStats {
  std::int64_t records = 0;
  std::array<std::int64_t, kFrameKindCount> frames{};  // records by FrameKind
  std::int64_t other_port = 0;          // UDP datagrams to another port than udp_port
  std::int64_t payloads_truncated = 0;  // captured shorter than sent; still handed on (the
                                        // decoder skips them as truncated)
  bool file_truncated = false;          // the file ended inside a record (PcapReader)
};

// Called for each completed rotation; an error stops the decoding and is returned.
using LidarScanSink = std::function<absl::Status(LidarScan&& scan)>;

// Reads every record of `path`, hands each UDP payload to `decoder` with the record's time as
// the host time, calls `on_scan` for every rotation it completes, and finally calls
// decoder->Finish() (delivering what that emits). Counts go to *stats (reset first).
// Errors: those of PcapReader (NotFound, InvalidArgument "<path>: ...", DataLoss for a
// corrupt record — rotations delivered before it stay delivered) and those of `on_scan`.
// Cost: one pass over the file; memory one record plus the decoder's open rotations.
absl::Status DecodeLidarPcap(const std::filesystem::path& path, const LidarPcapOptions& options,
                             LidarDecoder* decoder, const LidarScanSink& on_scan,
                             LidarPcapStats* stats);

}  // namespace linecal
