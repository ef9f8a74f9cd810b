#pragma once
// A LiDAR source (sensor_source.h): the sensor's UDP packets received on a socket
// (daemon/drivers/udp_receiver.h) and assembled into rotations by the LidarDecoder of the
// sensor's model and beam table (LidarBeamTableOf: the unit's angle file, else the model's
// table). Acquire receives until request.frames complete rotations were emitted (the decoder
// drops the partial rotation the reception starts in), then writes
//   <sensor_dir>/packets.pcap   every datagram received, as Ethernet/IPv4/UDP records with
//                               the kernel receive time (destination port = the bound port)
//   <sensor_dir>/scan_<k>.pcd   rotation k (0-based), stamped with its earliest point
// The socket is opened at each Acquire and closed when it returns.

#include <cstdint>
#include <memory>
#include <mutex>
#include <string>

#include "absl/status/status.h"
#include "daemon/drivers/udp_receiver.h"
#include "daemon/sources/sensor_source.h"
#include "station/sensors/lidar/lidar_decoder.h"

namespace linecal {

struct LidarUdpSourceConfig {
  std::string bind_address = "0.0.0.0";  // IPv4 literal
  std::uint16_t port = 2368;             // the Velodyne and Hesai factory default
  std::string multicast_group;           // empty: unicast or broadcast reception
  // Kernel receive buffer asked for; UdpReceiverOptions explains the 8 MiB.
  int receive_buffer_bytes = 8 << 20;

  // InvalidArgument naming the field (UdpReceiverOptions::Validate's checks).
  absl::Status Validate() const;
};

// What the last Acquire received: the numbers its progress details report.
struct LidarUdpCounters {
  UdpReceiverStats receiver;
  LidarDecoderStats decoder;
};

class LidarUdpSource : public SensorSource {
 public:
  explicit LidarUdpSource(LidarUdpSourceConfig config) : config_(std::move(config)) {}

  // SensorSource. Errors beyond the interface's:
  //   Unavailable       the socket cannot be bound or the group joined (the address named)
  //   DeadlineExceeded  "roof_lidar: no packets from 127.0.0.1:2368 in 2.0 s", or fewer
  //                     rotations than asked by the deadline (the count named)
  //   DataLoss          packets arrived but none decoded as the sensor's model (the count and
  //                     the skip reasons named)
  //   InvalidArgument   not a LiDAR, or its beam table cannot be loaded
  //   Internal          a socket or file error
  // Cost: the decoder's, plus one PCD write per rotation.
  absl::StatusOr<CaptureSensor> Acquire(const SensorModel& sensor,
                                        const AcquireRequest& request) override;
  // "udp 127.0.0.1:2368" (plus " group 239.1.1.1").
  std::string Describe() const override;

  // The counters of the last Acquire (zero before the first). Thread-safe.
  LidarUdpCounters last_counters() const;

 private:
  const LidarUdpSourceConfig config_;
  mutable std::mutex mutex_;
  LidarUdpCounters last_;
};

}  // namespace linecal
