// Fuzzes one LiDAR decoder (LINECAL_FUZZ_MODEL: 0 VLP-16, 1 Pandar64, 2 PandarXT-32; one
// target each). Each input is decoded twice: as one raw packet (size and header checks), and
// XORed over a valid rotation's worth of packets around the 0° wrap, so that mutations reach
// the point conversion and the rotation assembly. Invariants: no crash, counts that add up,
// finite points.
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include "station/sensors/lidar/lidar_decoder.h"

namespace {

using linecal::LidarModel;

constexpr LidarModel kModel = static_cast<LidarModel>(LINECAL_FUZZ_MODEL);

linecal::LidarBeamTable Table() {
  if (kModel == LidarModel::kVlp16) return *linecal::DefaultBeamTable(kModel);
  const int channels = linecal::GetLidarModelInfo(kModel).channels;
  std::string csv = "Channel,Elevation,Azimuth\n";
  for (int c = 1; c <= channels; ++c) {
    // Offsets of both signs, so beams cross 0° before and after their block.
    csv += std::to_string(c) + "," + std::to_string(15 - c % 30) + "," + (c % 2 ? "1.5" : "-1.5") +
           "\n";
  }
  return *linecal::ParseAngleCorrectionCsv(kModel, csv, "fuzz");
}

// Dual-return packets from 359° through the wrap to 1°.
std::vector<std::vector<std::uint8_t>> Templates() {
  linecal::LidarEncodeSettings s;
  s.model = kModel;
  s.return_mode = linecal::LidarReturnMode::kDual;
  s.first_column_time_ns = 1'700'000'000'000'000'000;
  const int per_packet = linecal::ColumnsPerPacket(kModel, 2);
  const int channels = linecal::GetLidarModelInfo(kModel).channels;
  std::vector<linecal::LidarColumn> cols(4 * per_packet);
  for (std::size_t k = 0; k < cols.size(); ++k) {
    cols[k].azimuth_centideg = static_cast<std::uint16_t>((35900 + 20 * k) % 36000);
    for (int e = 0; e < 2 * channels; ++e) {
      cols[k].echoes.push_back({1.0 + (e * 7 + k) % 40, static_cast<std::uint8_t>(e)});
    }
  }
  return *linecal::EncodeLidarPackets(s, cols);
}

void Check(const linecal::LidarDecoder& d, const std::vector<linecal::LidarScan>& scans) {
  const linecal::LidarDecoderStats& s = d.stats();
  if (s.packets != s.packets_decoded + s.skipped_total()) __builtin_trap();
  for (const linecal::LidarScan& scan : scans) {
    for (const linecal::LidarPoint& p : scan.points) {
      if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z)) __builtin_trap();
      if (p.ring >= linecal::GetLidarModelInfo(kModel).channels) __builtin_trap();
    }
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const linecal::LidarDecoder prototype = *linecal::LidarDecoder::Create(Table());
  static const std::vector<std::vector<std::uint8_t>> templates = Templates();
  std::vector<linecal::LidarScan> scans;

  linecal::LidarDecoder raw = prototype;
  raw.AddPacket({data, size}, 0, &scans);
  raw.Finish(&scans);
  Check(raw, scans);

  scans.clear();
  linecal::LidarDecoder near_valid = prototype;
  std::size_t at = 0;
  for (std::size_t i = 0; i < templates.size(); ++i) {
    std::vector<std::uint8_t> p = templates[i];
    for (std::size_t k = 0; k < p.size() && at < size; ++k) p[k] ^= data[at++];
    near_valid.AddPacket(p, 1'700'000'000'000'000'000 + static_cast<std::int64_t>(i) * 1'000'000,
                         &scans);
  }
  near_valid.Finish(&scans);
  Check(near_valid, scans);
  return 0;
}
