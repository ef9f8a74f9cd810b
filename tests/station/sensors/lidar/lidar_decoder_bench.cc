// LiDAR decoding throughput in MB/s of UDP payload, one core: packets to points, including
// rotation assembly (the payloads are read once, into memory). The bar is 200 MB/s.
// Run by hand: BUILD/bin/lidar_decoder_bench (docs/lidar-radar.md has the table).
#include <benchmark/benchmark.h>

#include <string>
#include <vector>

#include "station/io/pcap.h"
#include "station/sensors/lidar/lidar_decoder.h"
#include "tests/support/external_data.h"
#include "tests/support/lidar_recording.h"

namespace linecal {
namespace {

using testing_support::EncodedRecording;
using testing_support::ExternalPath;
using Recording = EncodedRecording;

// A real recording (docs/external-data.md); empty, and its benchmark skipped with the path
// named, when the external data is absent.
Recording FromPcap(const std::string& pcap, absl::StatusOr<LidarBeamTable> table) {
  Recording r;
  absl::StatusOr<PcapReader> reader = PcapReader::Open(pcap);
  if (!reader.ok() || !table.ok()) return r;
  r.table = *std::move(table);
  PcapRecord rec;
  while (reader->Next(&rec).value_or(false)) {
    const UdpFrame f = ParseUdpFrame(reader->info().link_type, rec.data);
    if (f.kind != FrameKind::kUdp) continue;
    r.payloads.emplace_back(f.payload.begin(), f.payload.end());
    r.times_ns.push_back(rec.time_ns);
  }
  return r;
}

void BM_Decode(benchmark::State& state, const Recording* rec) {
  absl::StatusOr<LidarDecoder> decoder = LidarDecoder::Create(rec->table);
  if (!decoder.ok() || rec->payloads.empty()) {
    state.SkipWithError(
        ("no recording; " + testing_support::MissingExternalMessage(ExternalPath("lidar")))
            .c_str());
    return;
  }
  std::int64_t bytes = 0;
  for (const auto& p : rec->payloads) bytes += static_cast<std::int64_t>(p.size());
  std::vector<LidarScan> scans;
  std::int64_t points = 0;
  for (auto _ : state) {
    for (std::size_t i = 0; i < rec->payloads.size(); ++i) {
      decoder->AddPacket(rec->payloads[i], rec->times_ns[i], &scans);
    }
    decoder->Finish(&scans);
    for (const LidarScan& s : scans) points += static_cast<std::int64_t>(s.points.size());
    benchmark::DoNotOptimize(scans.data());
    scans.clear();
  }
  state.SetBytesProcessed(state.iterations() * bytes);
  state.counters["packets/s"] = benchmark::Counter(
      static_cast<double>(state.iterations() * static_cast<std::int64_t>(rec->payloads.size())),
      benchmark::Counter::kIsRate);
  state.counters["points/s"] =
      benchmark::Counter(static_cast<double>(points), benchmark::Counter::kIsRate);
}

const Recording& Vlp16() {
  static const Recording r =
      FromPcap(ExternalPath("lidar/vlp16/packets.pcap"), DefaultBeamTable(LidarModel::kVlp16));
  return r;
}
const Recording& Pandar64() {
  static const Recording r = FromPcap(
      ExternalPath("lidar/pandar64/packets.pcap"),
      ReadAngleCorrectionCsv(LidarModel::kPandar64, ExternalPath("lidar/pandar64/Pandar64.csv")));
  return r;
}
const Recording& PandarXt32() {
  // No real PandarXT-32 recording exists: 4 turns of dual-return packets from the encoder.
  static const Recording r =
      testing_support::EncodeRecording(LidarModel::kPandarXt32, LidarReturnMode::kDual, 4.0);
  return r;
}

BENCHMARK_CAPTURE(BM_Decode, vlp16_dual_recorded, &Vlp16())->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_Decode, pandar64_dual_recorded, &Pandar64())->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_Decode, pandarxt32_dual_encoded, &PandarXt32())->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace linecal

BENCHMARK_MAIN();
