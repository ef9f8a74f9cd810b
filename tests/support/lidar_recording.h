#pragma once
// LiDAR recordings made with the project's own encoder (station/sensors/lidar/lidar_format.h), for
// tests that need packets but not a particular real sensor's: the pcap reader, the UDP
// receiver, the UDP source, the decode command. The tests that compare against the real
// recordings read those through tests/support/external_data.h instead.

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "station/sensors/lidar/lidar_format.h"

namespace linecal::testing_support {

// An angle-correction file in Hesai's layout for a Hesai model: elevations spread evenly over
// +15..-25 degrees, azimuth offsets of 1.0-2.6 degrees alternating in sign as the real files'
// are. Deterministic. Precondition: model is kPandar64 or kPandarXt32.
std::string SyntheticAngleCsv(LidarModel model);

// The beam table of a model: DefaultBeamTable for the VLP-16, the synthetic file otherwise.
LidarBeamTable SyntheticBeamTable(LidarModel model);

struct EncodedRecording {
  LidarBeamTable table;
  std::vector<std::vector<std::uint8_t>> payloads;  // UDP payloads, in order
  std::vector<std::int64_t> times_ns;               // capture time of each
};

// `turns` turns (whole packets, starting at azimuth 0) of the model at 10 Hz in `mode`, the
// first column at 2023-11-14 22:13:20 UTC. Every echo returns from 10-59 m, varying with the
// column and the beam, intensity 80. Deterministic. Precondition: 0 < turns <= 20.
EncodedRecording EncodeRecording(LidarModel model, LidarReturnMode mode, double turns);

// Writes the recording as Ethernet/IPv4/UDP records from the factory address and port, in
// nanosecond pcap. An error names the path.
absl::Status WriteRecordingPcap(const EncodedRecording& recording,
                                const std::filesystem::path& path);

}  // namespace linecal::testing_support
