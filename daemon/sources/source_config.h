#pragma once
// Which live source serves a sensor (station configuration, docs/daemon.md "Live sources"),
// and the factory that builds it. linecald.json's `source.sensors` parses into one
// SourceConfig per sensor name (daemon/core/daemon_config); the station core builds the
// sources once at start-up and checks that every sensor of every car model has one of its kind.

#include <memory>
#include <string>

#include "absl/status/statusor.h"
#include "daemon/sources/camera_sources.h"
#include "daemon/sources/can_radar_source.h"
#include "daemon/sources/lidar_udp_source.h"
#include "daemon/sources/sensor_source.h"
#include "station/model/car_model.h"

namespace linecal {

enum class SourceType { kAravis, kV4l2, kUdp, kSocketCan, kCandump };

// "aravis", "v4l2", "udp", "socketcan", "candump".
const char* SourceTypeName(SourceType type);
// The sensor kind a source type serves: cameras, LiDARs, radars.
SensorKind SourceTypeKind(SourceType type);

struct SourceConfig {
  SourceType type = SourceType::kUdp;
  // The member of `type`; the others are ignored. socketcan and candump share `can`
  // (can.input tells them apart).
  AravisCameraSourceConfig aravis;
  V4l2CameraSourceConfig v4l2;
  LidarUdpSourceConfig udp;
  CanRadarSourceConfig can;
};

// Validates the configuration of `config.type` and builds its source (no I/O: the device
// is opened at each Acquire). InvalidArgument naming the field ("port: must be ...").
absl::StatusOr<std::unique_ptr<SensorSource>> MakeSensorSource(const SourceConfig& config);

}  // namespace linecal
