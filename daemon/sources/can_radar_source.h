#pragma once
// A radar source (sensor_source.h): the radar's CAN frames, from a SocketCAN interface
// (daemon/drivers/socketcan.h) or from a recorded candump -l log that the station replays.
// The frames that belong to the radar are kept — ARS408: the cluster and object messages
// (0x600/0x701/0x702/0x60A/0x60B + 0x10 x the sensor's radar_sensor_id), ESR: the status
// (0x4E0) and the 64 track messages (0x500..0x53F); 11-bit data frames only — for the
// record time from the first of them, and written as `<sensor_dir>/can.log` (candump -l).
//
// Live: frames are read until the record time has passed since the first radar frame.
// Log: the file is read at each Acquire (a log replaced between cycles is used at the next);
// the record time selects the same span of the log, without waiting for it.

#include <chrono>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "daemon/drivers/socketcan.h"
#include "daemon/sources/sensor_source.h"

namespace linecal {

struct CanRadarSourceConfig {
  enum class Input { kSocketCan, kCandumpLog };
  Input input = Input::kSocketCan;
  // SocketCAN: the interface ("can0"). Log: when not empty, only frames of this interface.
  std::string interface;
  std::string log_path;  // log: the candump -l file
  // 50 measurement cycles of the slower supported radar (ARS408, 72 ms a cycle): enough
  // for the radar solver's yaw to settle (docs/lidar-radar.md).
  std::chrono::milliseconds record{3600};

  // InvalidArgument naming the field: an empty or over-long interface (SocketCAN), an empty
  // log path (log), a record time outside [1 ms, 60 s].
  absl::Status Validate() const;
};

class CanRadarSource : public SensorSource {
 public:
  // `syscalls`: how the SocketCAN interface is opened (tests replace it, socketcan.h).
  explicit CanRadarSource(CanRadarSourceConfig config,
                          SocketCanSyscalls syscalls = SocketCanSyscalls::Real())
      : config_(std::move(config)), syscalls_(syscalls) {}

  // SensorSource. Errors beyond the interface's, each naming the sensor and the interface or
  // file:
  //   Unavailable         no such interface, or the log cannot be opened
  //   FailedPrecondition  the kernel has no CAN, the interface is down or not CAN
  //   DeadlineExceeded    live: no frame of this radar before the deadline (a silent bus),
  //                       or the deadline came before the record time was over
  //   DataLoss            log: unparsable, or no frame of this radar in it (a silent log)
  //   InvalidArgument     not a radar, or a radar model without a CAN layout here
  // Cost: live, the record time; log, one read of the file.
  absl::StatusOr<CaptureSensor> Acquire(const SensorModel& sensor,
                                        const AcquireRequest& request) override;
  // "socketcan can0" or "candump /path/radar.log".
  std::string Describe() const override;

 private:
  absl::StatusOr<std::vector<CanFrame>> ReadLog(const SensorModel& sensor,
                                                const AcquireRequest& request) const;
  absl::StatusOr<std::vector<CanFrame>> ReadBus(const SensorModel& sensor,
                                                const AcquireRequest& request) const;

  const CanRadarSourceConfig config_;
  const SocketCanSyscalls syscalls_;
};

}  // namespace linecal
