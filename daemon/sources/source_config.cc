#include "daemon/sources/source_config.h"

#include "absl/strings/str_cat.h"

namespace linecal {

const char* SourceTypeName(SourceType type) {
  switch (type) {
    case SourceType::kAravis:
      return "aravis";
    case SourceType::kV4l2:
      return "v4l2";
    case SourceType::kUdp:
      return "udp";
    case SourceType::kSocketCan:
      return "socketcan";
    case SourceType::kCandump:
      return "candump";
  }
  return "?";
}

SensorKind SourceTypeKind(SourceType type) {
  switch (type) {
    case SourceType::kAravis:
    case SourceType::kV4l2:
      return SensorKind::kCamera;
    case SourceType::kUdp:
      return SensorKind::kLidar;
    case SourceType::kSocketCan:
    case SourceType::kCandump:
      return SensorKind::kRadar;
  }
  return SensorKind::kCamera;
}

absl::StatusOr<std::unique_ptr<SensorSource>> MakeSensorSource(const SourceConfig& config) {
  switch (config.type) {
    case SourceType::kAravis:
      if (absl::Status s = config.aravis.Validate(); !s.ok()) return s;
      return MakeAravisCameraSource(config.aravis);
    case SourceType::kV4l2:
      if (absl::Status s = config.v4l2.Validate(); !s.ok()) return s;
      return MakeV4l2CameraSource(config.v4l2);
    case SourceType::kUdp: {
      if (absl::Status s = config.udp.Validate(); !s.ok()) return s;
      return std::make_unique<LidarUdpSource>(config.udp);
    }
    case SourceType::kSocketCan:
    case SourceType::kCandump: {
      CanRadarSourceConfig can = config.can;
      can.input = config.type == SourceType::kSocketCan ? CanRadarSourceConfig::Input::kSocketCan
                                                        : CanRadarSourceConfig::Input::kCandumpLog;
      if (absl::Status s = can.Validate(); !s.ok()) return s;
      return std::make_unique<CanRadarSource>(can);
    }
  }
  return absl::InvalidArgumentError("type: unknown source type");
}

}  // namespace linecal
