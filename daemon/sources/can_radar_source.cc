#include "daemon/sources/can_radar_source.h"

#include <filesystem>
#include <optional>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "station/io/candump.h"
#include "station/sensors/radar/radar_decoder.h"
#include "station/sensors/radar/radar_format.h"

namespace linecal {
namespace {

namespace fs = std::filesystem;

// How long one read waits: the latency of noticing a cancel or the deadline.
constexpr std::chrono::milliseconds kPollInterval{50};
// Record times beyond a minute are a unit mistake (ms for s): a radar settles in seconds.
constexpr std::chrono::milliseconds kMaxRecord{60000};

// Whether `f` is a message of the radar (model, ARS408 sensor id); see the header.
bool BelongsTo(const CanFrame& f, RadarModel model, int sensor_id) {
  if (f.error || f.remote || f.extended || f.fd) return false;
  if (model == RadarModel::kArs408) {
    const std::optional<Ars408Id> id = ClassifyArs408Id(f.id);
    return id.has_value() && id->sensor_id == sensor_id;
  }
  return f.id == esr::kStatusId ||
         (f.id >= esr::kFirstTrackId &&
          f.id < esr::kFirstTrackId + static_cast<uint32_t>(esr::kTrackCount));
}

std::string RadarName(const SensorModel& sensor, RadarModel model) {
  return model == RadarModel::kArs408 ? absl::StrCat("ars408 sensor id ", sensor.radar_sensor_id)
                                      : "esr";
}

std::string Seconds(std::chrono::nanoseconds d) {
  return absl::StrFormat("%.1f s", std::chrono::duration<double>(d).count());
}

}  // namespace

absl::Status CanRadarSourceConfig::Validate() const {
  if (input == Input::kSocketCan &&
      (interface.empty() || interface.size() > kCanMaxInterfaceName)) {
    return absl::InvalidArgumentError(absl::StrCat("interface: '", interface, "' must have 1..",
                                                   kCanMaxInterfaceName, " characters"));
  }
  if (input == Input::kCandumpLog && log_path.empty())
    return absl::InvalidArgumentError("log: empty");
  if (record < std::chrono::milliseconds(1) || record > kMaxRecord) {
    return absl::InvalidArgumentError(
        absl::StrCat("record_ms: ", record.count(), " must be in [1, 60000]"));
  }
  return absl::OkStatus();
}

std::string CanRadarSource::Describe() const {
  return config_.input == CanRadarSourceConfig::Input::kSocketCan
             ? absl::StrCat("socketcan ", config_.interface)
             : absl::StrCat("candump ", config_.log_path);
}

absl::StatusOr<std::vector<CanFrame>> CanRadarSource::ReadLog(const SensorModel& sensor,
                                                              const AcquireRequest& request) const {
  const RadarModel model = *ParseRadarModel(sensor.model);
  absl::StatusOr<std::vector<CanFrame>> all = ReadCandumpLog(config_.log_path);
  if (absl::IsNotFound(all.status())) {
    return absl::UnavailableError(absl::StrCat(sensor.name, ": ", all.status().message()));
  }
  if (!all.ok())
    return absl::DataLossError(absl::StrCat(sensor.name, ": ", all.status().message()));
  std::vector<CanFrame> kept;
  for (const CanFrame& f : *all) {
    if (request.cancelled())
      return absl::CancelledError(absl::StrCat(sensor.name, ": cancelled reading the log"));
    if (!config_.interface.empty() && f.interface != config_.interface) continue;
    if (!BelongsTo(f, model, sensor.radar_sensor_id)) continue;
    if (!kept.empty() && f.time - kept.front().time >= config_.record) break;
    kept.push_back(f);
  }
  if (kept.empty()) {
    return absl::DataLossError(
        absl::StrCat(sensor.name, ": candump log '", config_.log_path, "' has no frame of ",
                     RadarName(sensor, model),
                     config_.interface.empty() ? "" : absl::StrCat(" on ", config_.interface), " (",
                     all->size(), " frames in all): the radar was silent"));
  }
  return kept;
}

absl::StatusOr<std::vector<CanFrame>> CanRadarSource::ReadBus(const SensorModel& sensor,
                                                              const AcquireRequest& request) const {
  const RadarModel model = *ParseRadarModel(sensor.model);
  absl::StatusOr<SocketCanReader> reader = SocketCanReader::Open(config_.interface, syscalls_);
  if (!reader.ok()) {
    // socketcan.h's messages start with the interface; a missing one is a device that
    // cannot be reached (SensorSource), the other failures keep their codes.
    const absl::StatusCode code =
        absl::IsNotFound(reader.status()) ? absl::StatusCode::kUnavailable : reader.status().code();
    return absl::Status(code, absl::StrCat(sensor.name, ": SocketCAN ", reader.status().message()));
  }
  const auto start = std::chrono::steady_clock::now();
  std::vector<CanFrame> kept;
  std::int64_t other_frames = 0;
  // Until the record time has passed since the first radar frame.
  std::optional<std::chrono::steady_clock::time_point> record_end;
  while (!record_end || std::chrono::steady_clock::now() < *record_end) {
    if (request.cancelled()) {
      return absl::CancelledError(absl::StrCat(sensor.name, ": cancelled after ", kept.size(),
                                               " frames on ", config_.interface));
    }
    const auto now = std::chrono::steady_clock::now();
    if (now >= request.deadline) {
      if (kept.empty()) {
        return absl::DeadlineExceededError(
            absl::StrCat(sensor.name, ": no frame of ", RadarName(sensor, model), " on ",
                         config_.interface, " in ", Seconds(request.deadline - start), " (",
                         other_frames, " other frames): the radar is silent"));
      }
      return absl::DeadlineExceededError(absl::StrCat(
          sensor.name, ": the deadline came after ", Seconds(now - start), " on ",
          config_.interface, ", before the record time of ", Seconds(config_.record), " was over"));
    }
    absl::StatusOr<std::optional<CanFrame>> frame = reader->Read(kPollInterval);
    if (!frame.ok())
      return absl::Status(frame.status().code(),
                          absl::StrCat(sensor.name, ": ", frame.status().message()));
    if (!frame->has_value()) continue;
    if (!BelongsTo(**frame, model, sensor.radar_sensor_id)) {
      ++other_frames;
      continue;
    }
    if (!record_end) record_end = std::chrono::steady_clock::now() + config_.record;
    kept.push_back(**std::move(frame));
    if (request.progress && kept.size() % 1000 == 1) {
      request.progress(absl::StrCat(kept.size(), " frames on ", config_.interface));
    }
  }
  return kept;
}

absl::StatusOr<CaptureSensor> CanRadarSource::Acquire(const SensorModel& sensor,
                                                      const AcquireRequest& request) {
  if (sensor.kind != SensorKind::kRadar) {
    return absl::InvalidArgumentError(absl::StrCat(
        sensor.name, ": a CAN radar source cannot serve a ", SensorKindName(sensor.kind)));
  }
  if (!ParseRadarModel(sensor.model)) {
    return absl::InvalidArgumentError(
        absl::StrCat(sensor.name, ": no CAN layout for radar model '", sensor.model, "'"));
  }
  absl::StatusOr<std::vector<CanFrame>> frames =
      config_.input == CanRadarSourceConfig::Input::kSocketCan ? ReadBus(sensor, request)
                                                               : ReadLog(sensor, request);
  if (!frames.ok()) return frames.status();

  const fs::path dir = fs::path(request.capture_dir) / request.sensor_dir;
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec)
    return absl::InternalError(
        absl::StrCat(sensor.name, ": cannot create '", dir.string(), "': ", ec.message()));
  const std::string rel = (fs::path(request.sensor_dir) / "can.log").string();
  if (absl::Status s = WriteCandumpLog(fs::path(request.capture_dir) / rel, *frames); !s.ok())
    return s;
  const RadarDecodeResult decoded =
      DecodeRadarFrames(*frames, *ParseRadarModel(sensor.model), RadarConventions{});
  if (request.progress) {
    request.progress(absl::StrCat(frames->size(), " frames, ", decoded.stats.cycles,
                                  " radar cycles (", decoded.stats.incomplete_cycles,
                                  " incomplete)"));
  }
  CaptureSensor out;
  out.name = sensor.name;
  out.kind = SensorKind::kRadar;
  out.can_log = CaptureFile{rel, std::chrono::duration_cast<std::chrono::nanoseconds>(
                                     frames->front().time.time_since_epoch())
                                     .count()};
  return out;
}

}  // namespace linecal
