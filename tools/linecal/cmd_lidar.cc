// linecal lidar decode: recorded LiDAR packets (pcap) to one PCD file per full rotation.
#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <system_error>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "station/sensors/lidar/lidar_decoder.h"
#include "station/sensors/lidar/lidar_format.h"
#include "station/sensors/lidar/lidar_pcap.h"
#include "station/sensors/lidar/pcd.h"
#include "tools/cli/command_line.h"
#include "tools/linecal/commands.h"

namespace linecal::tools {
namespace {

constexpr char kCommand[] = "lidar decode";
// A progress line on stderr every this many scans (10 s of a 10 Hz sensor).
constexpr int kProgressEveryScans = 100;

// What the flags ask for: the model, its decoder, the pcap filter, the recording and the
// output directory (created).
struct DecodeJob {
  LidarModel model;
  std::optional<LidarDecoder> decoder;
  LidarPcapOptions pcap_options;
  std::string pcap;
  std::filesystem::path out_dir;
};

// Reads the flags into a job and creates --out; the error names the flag and the value.
absl::StatusOr<DecodeJob> ReadDecodeJob(const cli::CommandLine& cl) {
  const std::optional<LidarModel> model = LidarModelFromName(cl.Get("model"));
  if (!model) {
    return absl::InvalidArgumentError(absl::StrCat("--model: unknown model '", cl.Get("model"),
                                                   "' (vlp16, pandar64, pandarxt32)"));
  }
  DecodeJob job{*model, std::nullopt, {}, cl.Get("pcap"), cl.Get("out")};
  const absl::StatusOr<LidarBeamTable> table =
      cl.Has("angles") ? ReadAngleCorrectionCsv(*model, cl.Get("angles"))
                       : DefaultBeamTable(*model);
  if (!table.ok()) {
    return absl::InvalidArgumentError(absl::StrCat("--angles: ", table.status().message()));
  }
  LidarDecoderOptions options;
  const absl::StatusOr<double> min_range = cl.GetDouble("min-range", options.min_range_m);
  const absl::StatusOr<double> max_range = cl.GetDouble("max-range", options.max_range_m);
  if (!min_range.ok()) return min_range.status();
  if (!max_range.ok()) return max_range.status();
  options.min_range_m = *min_range;
  options.max_range_m = *max_range;
  if (cl.Has("port")) {
    const absl::StatusOr<int> port = cl.GetInt("port", 0);
    if (!port.ok()) return port.status();
    if (*port < 1 || *port > 65535) {
      return absl::InvalidArgumentError(absl::StrCat("--port: ", *port, " is not in 1..65535"));
    }
    job.pcap_options.udp_port = static_cast<std::uint16_t>(*port);
  }
  absl::StatusOr<LidarDecoder> decoder = LidarDecoder::Create(*table, options);
  if (!decoder.ok()) {
    return absl::InvalidArgumentError(
        absl::StrCat("--min-range/--max-range: ", decoder.status().message()));
  }
  job.decoder.emplace(*std::move(decoder));
  std::error_code ec;
  if (!std::filesystem::is_regular_file(job.pcap, ec)) {
    return absl::InvalidArgumentError(absl::StrCat("--pcap: no such file '", job.pcap, "'"));
  }
  std::filesystem::create_directories(job.out_dir, ec);
  if (ec || !std::filesystem::is_directory(job.out_dir)) {
    return absl::InvalidArgumentError(
        absl::StrCat("--out: cannot create directory '", job.out_dir.string(), "'"));
  }
  return job;
}

// What a decode wrote and what the pcap held.
struct DecodeTotals {
  int written = 0;
  std::int64_t points_written = 0;
  LidarPcapStats pcap_stats;
};

// Decodes job.pcap and writes each full rotation as out_dir/scan-NNNNNN.pcd, with a progress
// line every kProgressEveryScans scans. The error is the reader's or the writer's.
absl::StatusOr<DecodeTotals> WriteScans(DecodeJob& job) {
  DecodeTotals totals;
  const absl::Status status = DecodeLidarPcap(
      job.pcap, job.pcap_options, &*job.decoder,
      [&](LidarScan&& scan) -> absl::Status {
        const std::filesystem::path file =
            job.out_dir / absl::StrFormat("scan-%06d.pcd", totals.written);
        if (absl::Status s = WritePcd(file, scan.points); !s.ok()) return s;
        ++totals.written;
        totals.points_written += static_cast<std::int64_t>(scan.points.size());
        if (totals.written % kProgressEveryScans == 0) {
          std::fprintf(stderr, "linecal %s: %d scans written\n", kCommand, totals.written);
        }
        return absl::OkStatus();
      },
      &totals.pcap_stats);
  if (!status.ok()) return status;
  return totals;
}

// The summary as one JSON object on stdout.
void PrintSummaryJson(const DecodeJob& job, const DecodeTotals& totals) {
  const LidarDecoderStats& stats = job.decoder->stats();
  const LidarPcapStats& pcap_stats = totals.pcap_stats;
  nlohmann::json skipped = nlohmann::json::object();
  for (int r = 0; r < kLidarSkipReasonCount; ++r) {
    skipped[LidarSkipReasonName(static_cast<LidarSkipReason>(r))] = stats.skipped[r];
  }
  nlohmann::json frames = nlohmann::json::object();
  for (int k = 0; k < kFrameKindCount; ++k) {
    frames[FrameKindName(static_cast<FrameKind>(k))] = pcap_stats.frames[k];
  }
  const nlohmann::json report = {{"model", GetLidarModelInfo(job.model).name},
                                 {"pcap", job.pcap},
                                 {"out", job.out_dir.string()},
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
                                 {"scans_written", totals.written},
                                 {"points_written", totals.points_written}};
  std::printf("%s\n", report.dump().c_str());
}

// The summary as text on stdout, one line per count; the frames not decoded and the skip
// reasons only where they are not zero.
void PrintSummaryText(const DecodeJob& job, const DecodeTotals& totals) {
  const LidarDecoderStats& stats = job.decoder->stats();
  const LidarPcapStats& pcap_stats = totals.pcap_stats;
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
  std::printf("scans written:       %d to %s (%lld points)\n", totals.written,
              job.out_dir.string().c_str(), static_cast<long long>(totals.points_written));
}

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
  absl::StatusOr<DecodeJob> job = ReadDecodeJob(cl);
  if (!job.ok()) return cli::BadInput(kCommand, std::string(job.status().message()));
  const absl::StatusOr<DecodeTotals> totals = WriteScans(*job);
  if (!totals.ok()) return cli::BadInput(kCommand, std::string(totals.status().message()));
  if (cl.Has("json")) {
    PrintSummaryJson(*job, *totals);
  } else {
    PrintSummaryText(*job, *totals);
  }
  return totals->written > 0 ? cli::kExitOk : cli::kExitNegative;
}

}  // namespace linecal::tools
