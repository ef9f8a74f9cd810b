#pragma once
// Live sensor sources: what serves one sensor's raw data to a cycle. Which source serves which
// sensor is station configuration (daemon_config, "sources"); the station core acquires every
// sensor of a cycle at once, one thread per sensor, each with its own deadline, and then
// calibrates the capture the sources wrote (station/pipeline), so that a live cycle and
// `linecal calibrate --capture` of its recording give identical results.
//
// A source writes its sensor's files into the cycle's capture directory, in the capture
// format (station/capture, docs/capture-format.md), and returns the manifest entry:
//   camera  PNG frames              (CaptureSensor::frames)
//   LiDAR   the UDP packets as pcap (::packets) and one PCD scan per rotation (::frames)
//   radar   the CAN traffic as a candump -l log (::can_log)
// A sensor whose source fails is reported by the core as that sensor's `error` with the
// status message as its reason; it never blocks the other sensors.

#include <atomic>
#include <chrono>
#include <functional>
#include <memory>
#include <string>

#include "absl/status/statusor.h"
#include "station/capture/capture.h"
#include "station/model/car_model.h"

namespace linecal {

struct AcquireRequest {
  std::string capture_dir;  // the cycle's capture directory; it exists
  std::string
      sensor_dir;  // relative to capture_dir, where this sensor's files go; the source creates it
  int frames = 1;  // camera frames, LiDAR rotations; radars record their configured time
  // Acquire returns by then (plus the time one blocking call may still take, at most the
  // source's own poll interval), with DeadlineExceeded if the data was not complete.
  std::chrono::steady_clock::time_point deadline;
  const std::atomic<bool>* cancel = nullptr;  // when set and true: return Cancelled promptly
  // Progress for the cycle's event stream ("frame 2/3"); may be empty. Called on Acquire's thread.
  std::function<void(const std::string& detail)> progress;

  bool cancelled() const { return cancel != nullptr && cancel->load(); }
};

class SensorSource {
 public:
  virtual ~SensorSource() = default;
  // Acquires `sensor`'s data for one cycle into request.capture_dir/request.sensor_dir and
  // returns its manifest entry (name and kind of `sensor`, paths relative to capture_dir).
  // Errors, each with a message that names the device and what went wrong:
  //   Unavailable       the device cannot be reached or opened (no such camera, interface down)
  //   DeadlineExceeded  the deadline passed before the data was complete (a silent sensor)
  //   DataLoss          data arrived broken and retries did not repair it
  //   Cancelled         request.cancel was set
  //   InvalidArgument   the sensor's kind does not fit this source
  // Thread safety: one Acquire at a time per source object; different sources run at once.
  virtual absl::StatusOr<CaptureSensor> Acquire(const SensorModel& sensor,
                                                const AcquireRequest& request) = 0;
  // What serves the sensor, for the station status and logs: "aravis Aravis-Fake-TEST01".
  virtual std::string Describe() const = 0;
};

}  // namespace linecal
