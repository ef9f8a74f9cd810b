#pragma once
// The point type of LiDAR scans: what the packet decoders produce, what PCD files hold and
// what the simulator writes. A plain struct (no PCL), so that headers stay cheap to include.

#include <cstdint>
#include <vector>

namespace linecal {

// One LiDAR return.
//   x, y, z     metres, in the LiDAR frame of the model that measured it (documented per
//               model in station/sensors/lidar/lidar_format.h). float: the sensors resolve 2-4 mm
//               at ranges below 300 m, where float's step is below 0.03 mm.
//   intensity   the vendor's reflectivity byte, 0..255 (calibrated reflectivity on VLP-16,
//               Pandar64 and PandarXT-32), as float so that other sources fit too.
//   ring        beam index sorted by elevation: 0 is the lowest beam, ring + 1 the next one
//               up (the ROS velodyne convention), for every model.
//   time_ns     when the beam fired: nanoseconds since the Unix epoch (UTC) on the sensor's
//               clock (see LidarDecoder for how the packet time fields are read).
struct LidarPoint {
  float x = 0.0f;
  float y = 0.0f;
  float z = 0.0f;
  float intensity = 0.0f;
  std::uint16_t ring = 0;
  std::int64_t time_ns = 0;

  bool operator==(const LidarPoint&) const = default;
};

// One full rotation: every return whose corrected azimuth lies in [0°, 360°) of that
// rotation, in the order the sensor measured them.
struct LidarScan {
  // Rotations counted from the first packet a decoder saw (the first full one is 1).
  std::int64_t rotation = 0;
  // Earliest time_ns of the points (0 when there are none).
  std::int64_t stamp_ns = 0;
  std::vector<LidarPoint> points;
};

}  // namespace linecal
