#pragma once
// What a cycle calibrates from: the capture source puts (or finds) the cycle's capture in its
// capture directory before the station core reads and calibrates it (daemon/core/
// station_core.h). One implementation per CycleSource of the station configuration:
//   simulator  simulates the car in the station into the directory (daemon/simstation/
//              simulator_source.h: only the simulated station includes the simulator);
//   replay     a recorded capture below the data root, calibrated as it is;
//   live       every sensor from its own SensorSource (daemon/sources), all at once, one
//              thread per sensor, then written as a capture (origin "station").
// Thread safety: one Acquire at a time (the core runs one cycle at a time); SensorSources
// from any thread.

#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "daemon/sources/sensor_source.h"
#include "daemon/sources/source_config.h"
#include "daemon/store/store.h"
#include "station/model/aligner.h"
#include "station/model/car_model.h"
#include "station/model/station_layout.h"

namespace linecal {

// Builds the source of a sensor from its configuration (MakeSensorSource by default).
using SensorSourceFactory = std::function<absl::StatusOr<std::unique_ptr<SensorSource>>(
    const std::string& sensor, const SourceConfig& config)>;

// One event of the cycle's stream: type, sensor (empty: cycle-wide), detail, verdict.
using CycleEventSink =
    std::function<void(EventType type, const std::string& sensor, const std::string& detail,
                       std::optional<Verdict> verdict)>;

// One cycle as a capture source needs it; the pointers outlive Acquire.
struct CaptureCycle {
  int64_t id = 0;
  const StationLayout* station = nullptr;
  const CarModel* car = nullptr;
  std::string vin;
  AlignerMeasurement aligner;
  int64_t started_ns = 0;  // the capture's time (Unix epoch)
  std::string dir;         // the capture directory: data root / the cycle's capture path
  int frames = 1;          // camera frames and LiDAR rotations per sensor
  const std::atomic<bool>* cancel = nullptr;  // set: stop at the next sensor, Cancelled
  CycleEventSink event;                       // sensor_acquired, sensor_progress, sensor_error
};

struct AcquiredCapture {
  // live: the sensors whose source failed, by name, with the status message; the capture in
  // `dir` holds the others.
  std::map<std::string, std::string> failures;
};

class CaptureSource {
 public:
  virtual ~CaptureSource() = default;
  // Makes the cycle's capture readable in cycle.dir. Errors: Cancelled when cycle.cancel was
  // set; else a status whose message is the cycle's reason ("acquisition_failed: ...",
  // "capture_unwritable: ...", "capture_unreadable: ..."), ResourceExhausted or ENOSPC in it
  // when the disk is full. Cost: the simulation, the acquisition (at most the acquire
  // deadline) or a few stat calls (replay).
  virtual absl::StatusOr<AcquiredCapture> Acquire(const CaptureCycle& cycle) = 0;
  // live: sensor name -> what serves it (SensorSource::Describe); else empty.
  virtual std::map<std::string, std::string> SensorSources() const { return {}; }
};

// Calibrates `data_root/capture` as it is. InvalidArgument when `capture` is not a relative
// path inside the data root or does not read (ReadCapture under `budget`): checked once here,
// and the folder's links again before every cycle.
absl::StatusOr<std::unique_ptr<CaptureSource>> MakeReplaySource(const std::string& data_root,
                                                                const std::string& capture,
                                                                const InputBudget& budget);

// Acquires every sensor from its source in `sources` (by sensor name), built once through
// `make_source` (empty: MakeSensorSource): every configured sensor exists in a car model with
// the kind its source serves, and every sensor of every car model has a source, else
// InvalidArgument naming "source.sensors.<name>". All sensors together get `deadline`.
absl::StatusOr<std::unique_ptr<CaptureSource>> MakeLiveSource(
    const std::map<std::string, SourceConfig>& sources, const SensorSourceFactory& make_source,
    const std::vector<CarModel>& cars, std::chrono::milliseconds deadline);

}  // namespace linecal
