// linecal lidar decode: recorded LiDAR packets (pcap) to one PCD file per full rotation.
#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <system_error>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "station/sensors/lidar/lidar_decoder.h"
#include "station/sensors/lidar/lidar_pcap.h"
#include "station/sensors/lidar/pcd.h"
#include "station/sensors/lidar/lidar_format.h"
#include "tools/cli/command_line.h"
#include "tools/linecal/commands.h"

namespace linecal::tools {
namespace {

constexpr char kCommand[] = "lidar decode";
// A progress line on stderr every this many scans (10 s of a 10 Hz sensor).
constexpr int kProgressEveryScans = 100;

}  // namespace

int RunLidarDecode(const Args& args) {
  cli::CommandLine cl(
      "linecal lidar decode --model vlp16|pandar64|pandarxt32 [--angles FILE] --pcap FILE "
      "--out DIR [--port N] [--min-range METRES] [--max-range METRES] [--json]",
      "Decodes the LiDAR packets of a pcap recording and writes one PCD file per full "
      "rotation, DIR/scan-000000.pcd, ... (fields x y z intensity ring time; metres in the "
      "sensor's frame, ring 0 = lowest beam, time in ns since the epoch). Partial rotations "
      "at the start and end of the recording are not written. Prints a summary; exits 1 when "
      "no full rotation was found.",
      {{"model", "NAME", "vlp16, pandar64 or pandarxt32", true},
       {"angles", "FILE",
        "angle correction CSV (Channel,Elevation,Azimuth); required for the Hesai models"},
       {"pcap", "FILE", "the recording (classic pcap, not pcapng)", true},
       {"out", "DIR", "output directory (created if missing)", true},
       {"port", "N", "only UDP datagrams to this destination port (default: all)"},
       {"min-range", "METRES", "drop nearer returns (default 0.3)"},
       {"max-range", "METRES", "drop farther returns (default 200)"},
       {"json", "", "print the summary as one JSON object"}});
  if (const std::optional<int> exit = cli::ParseOrExit(cl, kCommand, args)) return *exit;

  const std::optional<LidarModel> model = LidarModelFromName(cl.Get("model"));
  if (!model) {
    return cli::BadInput(kCommand, absl::StrCat("--model: unknown model '", cl.Get("model"),
                                                "' (vlp16, pandar64, pandarxt32)"));
  }
  const absl::StatusOr<LidarBeamTable> table =
      cl.Has("angles") ? ReadAngleCorrectionCsv(*model, cl.Get("angles"))
                       : DefaultBeamTable(*model);
  if (!table.ok()) {
    return cli::BadInput(kCommand, absl::StrCat("--angles: ", table.status().message()));
  }
  LidarDecoderOptions options;
  const absl::StatusOr<double> min_range = cl.GetDouble("min-range", options.min_range_m);
  const absl::StatusOr<double> max_range = cl.GetDouble("max-range", options.max_range_m);
  if (!min_range.ok()) return cli::BadInput(kCommand, std::string(min_range.status().message()));
  if (!max_range.ok()) return cli::BadInput(kCommand, std::string(max_range.status().message()));
  options.min_range_m = *min_range;
  options.max_range_m = *max_range;
  LidarPcapOptions pcap_options;
  if (cl.Has("port")) {
    const absl::StatusOr<int> port = cl.GetInt("port", 0);
    if (!port.ok()) return cli::BadInput(kCommand, std::string(port.status().message()));
    if (*port < 1 || *port > 65535) {
      return cli::BadInput(kCommand, absl::StrCat("--port: ", *port, " is not in 1..65535"));
    }
    pcap_options.udp_port = static_cast<std::uint16_t>(*port);
  }
  absl::StatusOr<LidarDecoder> decoder = LidarDecoder::Create(*table, options);
  if (!decoder.ok()) {
    return cli::BadInput(kCommand,
                         absl::StrCat("--min-range/--max-range: ", decoder.status().message()));
  }
  const std::string pcap = cl.Get("pcap");
  std::error_code ec;
  if (!std::filesystem::is_regular_file(pcap, ec)) {
    return cli::BadInput(kCommand, absl::StrCat("--pcap: no such file '", pcap, "'"));
  }
  const std::filesystem::path out_dir = cl.Get("out");
  std::filesystem::create_directories(out_dir, ec);
  if (ec || !std::filesystem::is_directory(out_dir)) {
    return cli::BadInput(kCommand,
                         absl::StrCat("--out: cannot create directory '", out_dir.string(), "'"));
  }

  int written = 0;
  std::int64_t points_written = 0;
  LidarPcapStats pcap_stats;
  const absl::Status status = DecodeLidarPcap(
      pcap, pcap_options, &*decoder,
      [&](LidarScan&& scan) -> absl::Status {
        const std::filesystem::path file = out_dir / absl::StrFormat("scan-%06d.pcd", written);
        if (absl::Status s = WritePcd(file, scan.points); !s.ok()) return s;
        ++written;
        points_written += static_cast<std::int64_t>(scan.points.size());
        if (written % kProgressEveryScans == 0) {
          std::fprintf(stderr, "linecal %s: %d scans written\n", kCommand, written);
        }
        return absl::OkStatus();
      },
      &pcap_stats);
  if (!status.ok()) return cli::BadInput(kCommand, std::string(status.message()));

  const LidarDecoderStats& stats = decoder->stats();
  nlohmann::json skipped = nlohmann::json::object();
  for (int r = 0; r < kLidarSkipReasonCount; ++r) {
    skipped[LidarSkipReasonName(static_cast<LidarSkipReason>(r))] = stats.skipped[r];
  }
  nlohmann::json frames = nlohmann::json::object();
  for (int k = 0; k < kFrameKindCount; ++k) {
    frames[FrameKindName(static_cast<FrameKind>(k))] = pcap_stats.frames[k];
  }
  if (cl.Has("json")) {
    const nlohmann::json report = {{"model", GetLidarModelInfo(*model).name},
                                   {"pcap", pcap},
                                   {"out", out_dir.string()},
                                   {"records", pcap_stats.records},
                                   {"frames", frames},
                                   {"other_port", pcap_stats.other_port},
                                   {"file_truncated", pcap_stats.file_truncated},
                                   {"packets_read", stats.packets},
                                   {"packets_decoded", stats.packets_decoded},
                                   {"packets_skipped", stats.skipped_total()},
                                   {"skipped", skipped},
                                   {"packets_without_date", stats.packets_without_date},
                                   {"partial_rotations", stats.partial_rotations},
                                   {"scans_written", written},
                                   {"points_written", points_written}};
    std::printf("%s\n", report.dump().c_str());
  } else {
    std::printf("pcap records:        %lld%s\n", static_cast<long long>(pcap_stats.records),
                pcap_stats.file_truncated ? " (file ends inside a record)" : "");
    std::string other;
    for (int k = 1; k < kFrameKindCount; ++k) {
      if (pcap_stats.frames[k] == 0) continue;
      absl::StrAppend(&other, other.empty() ? "" : ", ", FrameKindName(static_cast<FrameKind>(k)),
                      " ", pcap_stats.frames[k]);
    }
    if (pcap_stats.other_port > 0) {
      absl::StrAppend(&other, other.empty() ? "" : ", ", "other port ", pcap_stats.other_port);
    }
    if (!other.empty()) std::printf("not decoded:         %s\n", other.c_str());
    std::printf("packets read:        %lld\n", static_cast<long long>(stats.packets));
    std::printf("packets decoded:     %lld\n", static_cast<long long>(stats.packets_decoded));
    std::string reasons;
    for (int r = 0; r < kLidarSkipReasonCount; ++r) {
      if (stats.skipped[r] == 0) continue;
      absl::StrAppend(&reasons, reasons.empty() ? " (" : ", ",
                      LidarSkipReasonName(static_cast<LidarSkipReason>(r)), " ", stats.skipped[r]);
    }
    if (!reasons.empty()) reasons += ")";
    std::printf("packets skipped:     %lld%s\n", static_cast<long long>(stats.skipped_total()),
                reasons.c_str());
    if (stats.packets_without_date > 0) {
      std::printf("without a date:      %lld (time from the capture clock)\n",
                  static_cast<long long>(stats.packets_without_date));
    }
    std::printf("partial rotations:   %lld (not written)\n",
                static_cast<long long>(stats.partial_rotations));
    std::printf("scans written:       %d to %s (%lld points)\n", written, out_dir.string().c_str(),
                static_cast<long long>(points_written));
  }
  return written > 0 ? cli::kExitOk : cli::kExitNegative;
}

}  // namespace linecal::tools
