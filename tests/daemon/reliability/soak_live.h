#pragma once
// The soak's live sources (docs/reliability.md, "Live sources"): the soak car's LiDARs and
// radars served as linecald serves them on the line, so that faults of the link and of the
// sensor itself reach the daemon through its real sources. Each LiDAR is the UDP source on a
// port of 127.0.0.1, fed by a sender thread with the pristine capture's packets; each radar is
// the candump source on the pristine capture's CAN log. Cameras have no live source that
// replays files (their live faults, GigE packet loss, are tests/tools/live_cycle_test.cc's).
//
// Every cycle runs on a core of its own (its own data root and database, built and destroyed
// with the cycle), so the soak's core, store and descriptor counts stay as they were.

#include <chrono>
#include <cstdint>
#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "daemon/core/station_core.h"
#include "station/capture/capture.h"
#include "tests/daemon/loopback_udp.h"

namespace linecal::reliability {

// What one live cycle suffers: `lidar`'s packets sent with `send` (lost, cut, stopped), and/or
// `silent_radar`'s CAN log replaced by an empty one. Empty names: nothing.
struct LiveFault {
  std::string lidar;
  testing_daemon::SendFaults send;
  std::string silent_radar;
};

struct LiveCycle {
  StoredCycle stored;  // elapsed times zeroed, as the soak compares results
  std::chrono::steady_clock::duration wall{};
};

class LiveRig {
 public:
  // The car model id of the live core's car: the soak's car cut to its LiDARs and radars.
  static constexpr char kCarId[] = "soak_live";
  // How long a silent sensor is waited for: the cycle must end within it plus the compute.
  static constexpr std::chrono::milliseconds kAcquireDeadline{1500};

  // From the soak's scratch directory `dir`, its pristine capture (`pristine`, read as
  // `layout`), its car file and core configuration. An empty rig (no LiDAR, no radar) when the
  // car has neither. Errors: files that cannot be read or written (named).
  static absl::StatusOr<LiveRig> Create(const std::filesystem::path& dir,
                                        const std::filesystem::path& pristine,
                                        const Capture& layout, const std::string& car_path,
                                        const StationCoreConfig& soak_config);

  bool empty() const { return lidars_.empty() && radars_.empty(); }
  const std::vector<std::string>& lidars() const { return lidars_; }
  const std::vector<std::string>& radars() const { return radars_; }
  // LiDAR packets in the pristine recording (one rotation and its partial neighbours).
  std::size_t PacketCount(const std::string& lidar) const { return packets_.at(lidar).size(); }

  // Runs one cycle of `request` (car kCarId) on a fresh live core with `fault`. Errors: a core
  // that cannot be built, a refused start, a cycle that cannot be read back (each named).
  absl::StatusOr<LiveCycle> Run(const CycleRequest& request, const LiveFault& fault) const;

 private:
  std::filesystem::path dir_;
  StationCoreConfig config_;  // the live core's; data root and database under dir_/live
  std::vector<std::string> lidars_, radars_;
  std::map<std::string, std::vector<testing_daemon::Payload>> packets_;  // per LiDAR
  std::filesystem::path empty_log_;                                      // a silent bus
};

}  // namespace linecal::reliability
