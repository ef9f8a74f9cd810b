#include "tests/support/lidar_recording.h"

#include <cmath>

#include "station/io/pcap.h"

namespace linecal::testing_support {

std::string SyntheticAngleCsv(LidarModel model) {
  const int channels = GetLidarModelInfo(model).channels;
  std::string csv = "Laser id,Elevation,Azimuth\n";
  for (int c = 0; c < channels; ++c) {
    const double elevation_deg = 15.0 - 40.0 * c / (channels - 1);
    // Off the 0.2 degree column grid, as real offsets are (-1.042 ...): no beam lands exactly
    // on a rotation boundary.
    const double azimuth_deg = (c % 2 == 0 ? 1.0 : -1.0) * (1.042 + 0.5 * (c % 4));
    csv += std::to_string(c + 1) + "," + std::to_string(elevation_deg) + "," +
           std::to_string(azimuth_deg) + "\n";
  }
  return csv;
}

LidarBeamTable SyntheticBeamTable(LidarModel model) {
  if (model == LidarModel::kVlp16) return *DefaultBeamTable(model);
  return *ParseAngleCorrectionCsv(model, SyntheticAngleCsv(model), "synthetic.csv");
}

EncodedRecording EncodeRecording(LidarModel model, LidarReturnMode mode, double turns) {
  const LidarModelInfo& info = GetLidarModelInfo(model);
  const int returns = mode == LidarReturnMode::kDual ? 2 : 1;
  const int per_packet = ColumnsPerPacket(model, returns);
  // 0.2 degrees per column (0.18 on the XT-32), as the simulator spaces them at 10 Hz.
  const int step_centideg = model == LidarModel::kPandarXt32 ? 18 : 20;
  const int per_turn = 36000 / step_centideg;
  const int packets = static_cast<int>(std::ceil(turns * per_turn / per_packet));
  LidarEncodeSettings settings;
  settings.model = model;
  settings.return_mode = mode;
  settings.first_column_time_ns = 1'700'000'000'000'000'000;
  std::vector<LidarColumn> columns(static_cast<std::size_t>(packets) * per_packet);
  for (std::size_t k = 0; k < columns.size(); ++k) {
    columns[k].azimuth_centideg = static_cast<std::uint16_t>(k * step_centideg % 36000);
    for (int e = 0; e < info.channels * returns; ++e) {
      columns[k].echoes.push_back({10.0 + static_cast<double>((k + 7 * e) % 50), 80});
    }
  }
  EncodedRecording r;
  r.table = SyntheticBeamTable(model);
  r.payloads = *EncodeLidarPackets(settings, columns);
  for (std::size_t i = 0; i < r.payloads.size(); ++i) {
    r.times_ns.push_back(settings.first_column_time_ns +
                         static_cast<std::int64_t>(i) * per_packet * info.column_period_ns);
  }
  return r;
}

absl::Status WriteRecordingPcap(const EncodedRecording& recording,
                                const std::filesystem::path& path) {
  absl::StatusOr<PcapWriter> writer = PcapWriter::Create(path);
  if (!writer.ok()) return writer.status();
  for (std::size_t i = 0; i < recording.payloads.size(); ++i) {
    absl::Status s = writer->WriteUdp(recording.times_ns[i], UdpEndpoints{}, recording.payloads[i]);
    if (!s.ok()) return s;
  }
  return writer->Close();
}

}  // namespace linecal::testing_support
