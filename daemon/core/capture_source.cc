#include "daemon/core/capture_source.h"

#include <filesystem>
#include <system_error>
#include <thread>
#include <utility>

#include "absl/strings/str_cat.h"
#include "station/capture/capture.h"

namespace linecal {
namespace {

namespace fs = std::filesystem;

class ReplaySource : public CaptureSource {
 public:
  ReplaySource(std::string data_root, std::string capture)
      : data_root_(std::move(data_root)), capture_(std::move(capture)) {}

  absl::StatusOr<AcquiredCapture> Acquire(const CaptureCycle&) override {
    // The folder may have become a link out of data_root since the start (MakeReplaySource
    // checked it then): checked again before every replayed cycle reads it.
    absl::StatusOr<fs::path> inside =
        ResolveInside(data_root_, capture_, absl::StrCat("'", capture_, "'"), "data_root");
    if (!inside.ok()) {
      return absl::Status(
          inside.status().code(),
          absl::StrCat("capture_unreadable: source.capture: ", inside.status().message()));
    }
    return AcquiredCapture{};
  }

 private:
  const std::string data_root_;
  const std::string capture_;
};

class LiveSource : public CaptureSource {
 public:
  LiveSource(std::map<std::string, std::unique_ptr<SensorSource>> sources,
             std::chrono::milliseconds deadline)
      : sources_(std::move(sources)), deadline_(deadline) {}

  absl::StatusOr<AcquiredCapture> Acquire(const CaptureCycle& cycle) override {
    std::error_code ec;
    fs::create_directories(cycle.dir, ec);
    if (ec) {
      return absl::InternalError(
          absl::StrCat("acquisition_failed: cannot create '", cycle.dir, "': ", ec.message()));
    }
    CaptureManifest manifest;
    manifest.vin = cycle.vin;
    manifest.car_model = cycle.car->id;
    manifest.time_ns = cycle.started_ns;
    manifest.origin = "station";
    manifest.aligner = cycle.aligner;
    AcquiredCapture acquired;
    manifest.sensors = AcquireSensors(cycle, &acquired.failures);
    if (cycle.cancel->load()) return absl::CancelledError("cancelled");
    if (absl::Status s = WriteCapture(cycle.dir, manifest, *cycle.station, *cycle.car); !s.ok()) {
      return absl::Status(s.code(), absl::StrCat("capture_unwritable: ", s.message()));
    }
    return acquired;
  }

  std::map<std::string, std::string> SensorSources() const override {
    std::map<std::string, std::string> described;
    for (const auto& [name, source] : sources_) described[name] = source->Describe();
    return described;
  }

 private:
  // Acquires every sensor of the cycle's car into its directory at once, one thread each;
  // returns the sensors acquired (car model order) and, per sensor that failed, its status
  // message in `failures`. Each sensor's acquisition, progress or error is an event.
  std::vector<CaptureSensor> AcquireSensors(const CaptureCycle& cycle,
                                            std::map<std::string, std::string>* failures) {
    const auto deadline = std::chrono::steady_clock::now() + deadline_;
    const std::vector<SensorModel>& models = cycle.car->sensors;
    std::vector<absl::StatusOr<CaptureSensor>> acquired(models.size(),
                                                        absl::UnknownError("not acquired"));
    std::vector<std::thread> threads;
    for (size_t i = 0; i < models.size(); ++i) {
      threads.emplace_back([&, i] {
        const SensorModel& sensor = models[i];
        AcquireRequest request;
        request.capture_dir = cycle.dir;
        request.sensor_dir = sensor.name;
        request.frames = cycle.frames;
        request.deadline = deadline;
        request.cancel = cycle.cancel;
        request.progress = [&](const std::string& detail) {
          cycle.event(EventType::kSensorProgress, sensor.name, detail, std::nullopt);
        };
        acquired[i] = sources_.at(sensor.name)->Acquire(sensor, request);
        if (acquired[i].ok()) {
          const CaptureSensor& got = *acquired[i];
          cycle.event(EventType::kSensorAcquired, sensor.name,
                      absl::StrCat(got.frames.size(), " frames", got.packets ? ", packets" : "",
                                   got.can_log ? ", CAN log" : ""),
                      std::nullopt);
        } else {
          cycle.event(EventType::kSensorError, sensor.name,
                      std::string(acquired[i].status().message()), Verdict::kError);
        }
      });
    }
    for (std::thread& t : threads) t.join();
    std::vector<CaptureSensor> sensors;
    for (size_t i = 0; i < models.size(); ++i) {
      if (acquired[i].ok()) {
        sensors.push_back(*std::move(acquired[i]));
      } else {
        (*failures)[models[i].name] = std::string(acquired[i].status().message());
      }
    }
    return sensors;
  }

  // By sensor name; used by one cycle at a time.
  const std::map<std::string, std::unique_ptr<SensorSource>> sources_;
  const std::chrono::milliseconds deadline_;
};

// The error of a configured source for `name` that no car model, or one of another kind,
// has; OK when every car model that has the sensor has it of the source's kind.
absl::Status CheckSourceFits(const std::string& name, const SourceConfig& source,
                             const std::vector<CarModel>& cars) {
  bool found = false;
  for (const CarModel& car : cars) {
    const SensorModel* sensor = car.FindSensor(name);
    if (sensor == nullptr) continue;
    found = true;
    if (SourceTypeKind(source.type) != sensor->kind) {
      return absl::InvalidArgumentError(
          absl::StrCat("source.sensors.", name, ".type: '", SourceTypeName(source.type),
                       "' serves ", SensorKindName(SourceTypeKind(source.type)), "s, but '", name,
                       "' of car model '", car.id, "' is a ", SensorKindName(sensor->kind)));
    }
  }
  if (!found) {
    return absl::InvalidArgumentError(
        absl::StrCat("source.sensors.", name, ": no car model has a sensor '", name, "'"));
  }
  return absl::OkStatus();
}

}  // namespace

absl::StatusOr<std::unique_ptr<CaptureSource>> MakeReplaySource(const std::string& data_root,
                                                                const std::string& capture,
                                                                const InputBudget& budget) {
  const fs::path rel(capture);
  if (rel.empty() || rel.is_absolute() || rel.lexically_normal().string().rfind("..", 0) == 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("source.capture: '", capture, "' must be a path inside data_root"));
  }
  absl::StatusOr<Capture> read = ReadCapture((fs::path(data_root) / rel).string(), budget);
  if (!read.ok()) return read.status();
  return std::make_unique<ReplaySource>(data_root, capture);
}

absl::StatusOr<std::unique_ptr<CaptureSource>> MakeLiveSource(
    const std::map<std::string, SourceConfig>& sources, const SensorSourceFactory& make_source,
    const std::vector<CarModel>& cars, std::chrono::milliseconds deadline) {
  std::map<std::string, std::unique_ptr<SensorSource>> built_sources;
  for (const auto& [name, source] : sources) {
    if (absl::Status s = CheckSourceFits(name, source, cars); !s.ok()) return s;
    absl::StatusOr<std::unique_ptr<SensorSource>> built =
        make_source ? make_source(name, source) : MakeSensorSource(source);
    if (!built.ok()) {
      return absl::Status(built.status().code(),
                          absl::StrCat("source.sensors.", name, ".", built.status().message()));
    }
    built_sources[name] = std::move(*built);
  }
  for (const CarModel& car : cars) {
    for (const SensorModel& sensor : car.sensors) {
      if (!built_sources.contains(sensor.name)) {
        return absl::InvalidArgumentError(absl::StrCat("source.sensors: no source for sensor '",
                                                       sensor.name, "' of car model '", car.id,
                                                       "'"));
      }
    }
  }
  return std::make_unique<LiveSource>(std::move(built_sources), deadline);
}

}  // namespace linecal
