#pragma once
// The simulated station on the wire: serves a recorded (or simulated) capture as live sensors,
// so that linecald's live sources are exercised end to end over the real protocols —
//   cameras  one of Aravis's in-process fake GigE Vision cameras per camera sensor, each on its
//            own IPv4 address (GigE Vision's control port is fixed, so one camera per address),
//            serving the sensor's first recorded frame over the real GVSP stream;
//   LiDARs   the sensor's recorded packets sent over UDP to a port of their own, looped with
//            their recorded timing, as a spinning LiDAR sends without end;
//   radars   the sensor's recorded candump log, read by linecald's `candump` source (this
//            kernel has no CAN interfaces to send on).
// `LiveSourceConfig()` is the linecald `source` object that points every sensor at what serves
// it. Used by tools/demo (`linecal serve-sensors`) and the end-to-end tests.

#include <atomic>
#include <cstdint>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>
#include <vector>

#include "absl/status/statusor.h"
#include "daemon/simstation/fake_gige_camera.h"
#include "station/capture/capture.h"

namespace linecal {

struct SensorServerOptions {
  std::string capture_dir;
  // One IPv4 address per camera sensor, in the manifest's order. Addresses other than
  // 127.0.0.1 must exist on an interface (`ip addr add 127.0.0.2/8 dev lo`).
  std::vector<std::string> camera_addresses = {"127.0.0.1"};
  // Share of GVSP stream packets the fake cameras drop (fault injection), [0, 1).
  double camera_lost_ratio = 0;
  // Frames per second of each fake camera: a cycle takes one or a few frames, and five
  // cameras at Aravis's 25 frames/s overrun loopback's socket buffers on a 2-core machine.
  double camera_fps = 5;
  std::string lidar_address = "127.0.0.1";
  // LiDAR k (in the manifest's order) is sent to lidar_first_port + k.
  std::uint16_t lidar_first_port = 2368;
  // Replay speed: 1 keeps the recorded packet timing; 0 sends as fast as the socket takes.
  double lidar_speed = 1;

  absl::Status Validate() const;
};

class SensorServer {
 public:
  // Reads the capture (ReadCapture), starts a fake camera per camera sensor and a sender
  // thread per LiDAR. InvalidArgument naming the option (fewer camera addresses than camera
  // sensors, a bad ratio); Unavailable naming the address when a fake camera cannot start;
  // the capture's own errors as ReadCapture gives them.
  static absl::StatusOr<std::unique_ptr<SensorServer>> Start(const SensorServerOptions& options);
  // Stops the senders and the cameras.
  ~SensorServer();
  SensorServer(const SensorServer&) = delete;
  SensorServer& operator=(const SensorServer&) = delete;

  // {"type": "live", "sensors": {...}}: an aravis source per camera (the fake camera's device
  // id), a udp source per LiDAR (bound to lidar_address and its port), a candump source per
  // radar (the capture's log, absolute path).
  nlohmann::json LiveSourceConfig() const;
  const Capture& capture() const { return capture_; }
  // UDP datagrams sent so far, all LiDARs together.
  std::int64_t lidar_datagrams_sent() const { return datagrams_sent_.load(); }

 private:
  SensorServer(SensorServerOptions options, Capture capture);
  absl::Status StartLidar(const CaptureSensor& sensor, std::uint16_t port);

  const SensorServerOptions options_;
  const Capture capture_;
  std::vector<std::pair<std::string, std::unique_ptr<FakeGigeCamera>>>
      cameras_;                                                     // sensor name, camera
  std::vector<std::pair<std::string, std::uint16_t>> lidar_ports_;  // sensor name, port
  std::vector<std::thread> senders_;
  std::atomic<bool> stop_{false};
  std::atomic<std::int64_t> datagrams_sent_{0};
};

}  // namespace linecal
