// LiDAR decoding throughput in MB/s of UDP payload, one core: packets to points, including
// rotation assembly (the payloads are read once, into memory). The bar is 200 MB/s.
// Run by hand: BUILD/bin/lidar_decoder_bench (docs/lidar-radar.md has the table).
#include <benchmark/benchmark.h>

#include <string>
#include <vector>

#include "daemon/drivers/lidar_decoder.h"
#include "station/io/pcap.h"

namespace linecal {
namespace {

const std::string kData = std::string(LINECAL_SOURCE_DIR) + "/../shared/data/lidar/";

struct Recording {
  LidarBeamTable table;
  std::vector<std::vector<std::uint8_t>> payloads;
  std::vector<std::int64_t> times_ns;
};

Recording FromPcap(const std::string& pcap, LidarBeamTable table) {
  Recording r;
  r.table = std::move(table);
  absl::StatusOr<PcapReader> reader = PcapReader::Open(pcap);
  if (!reader.ok()) return r;
  PcapRecord rec;
  while (reader->Next(&rec).value_or(false)) {
    const UdpFrame f = ParseUdpFrame(reader->info().link_type, rec.data);
    if (f.kind != FrameKind::kUdp) continue;
    r.payloads.emplace_back(f.payload.begin(), f.payload.end());
    r.times_ns.push_back(rec.time_ns);
  }
  return r;
}

// PandarXT-32 (no recording exists): 4 turns of dual-return packets from the encoder, every
// beam hitting something 10-60 m away.
Recording Xt32() {
  Recording r;
  std::string csv = "Channel,Elevation,Azimuth\n";
  for (int c = 1; c <= 32; ++c) {
    csv += std::to_string(c) + "," + std::to_string(16 - c) + "," + (c % 2 ? "1" : "-1") + "\n";
  }
  r.table = *ParseAngleCorrectionCsv(LidarModel::kPandarXt32, csv, "xt32");
  LidarEncodeSettings s;
  s.model = LidarModel::kPandarXt32;
  s.return_mode = LidarReturnMode::kDual;
  s.first_column_time_ns = 1'700'000'000'000'000'000;
  std::vector<LidarColumn> cols(8000);  // 4 turns of 0.18°
  for (int k = 0; k < 8000; ++k) {
    cols[k].azimuth_centideg = static_cast<std::uint16_t>(k * 18 % 36000);
    for (int e = 0; e < 64; ++e) cols[k].echoes.push_back({10.0 + (k + e) % 50, 80});
  }
  r.payloads = *EncodeLidarPackets(s, cols);
  for (std::size_t i = 0; i < r.payloads.size(); ++i) {
    r.times_ns.push_back(s.first_column_time_ns + static_cast<std::int64_t>(i) * 200'000);
  }
  return r;
}

void BM_Decode(benchmark::State& state, const Recording* rec) {
  absl::StatusOr<LidarDecoder> decoder = LidarDecoder::Create(rec->table);
  if (!decoder.ok() || rec->payloads.empty()) {
    state.SkipWithError("no recording");
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
      FromPcap(kData + "vlp16/packets.pcap", *DefaultBeamTable(LidarModel::kVlp16));
  return r;
}
const Recording& Pandar64() {
  static const Recording r =
      FromPcap(kData + "pandar64/packets.pcap",
               *ReadAngleCorrectionCsv(LidarModel::kPandar64, kData + "pandar64/Pandar64.csv"));
  return r;
}
const Recording& PandarXt32() {
  static const Recording r = Xt32();
  return r;
}

BENCHMARK_CAPTURE(BM_Decode, vlp16_dual_recorded, &Vlp16())->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_Decode, pandar64_dual_recorded, &Pandar64())->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_Decode, pandarxt32_dual_encoded, &PandarXt32())->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace linecal

BENCHMARK_MAIN();
