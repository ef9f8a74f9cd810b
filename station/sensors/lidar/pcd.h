#pragma once
// PCD point cloud files (PCL's format, v0.7) for LiDAR scans: `linecal lidar decode` output,
// capture scans, `linecal detect --cloud` input. The implementation uses PCL's reader and
// writer; this header stays free of PCL so that including it is cheap.
//
// Written files hold one LidarPoint per point with the fields (docs/interfaces.md)
//   x y z      F 4   metres, the LiDAR frame
//   intensity  F 4
//   ring       U 2   0 = lowest beam
//   time       I 8   ns since the epoch
// Reading accepts any PCD with x, y and z fields (ascii, binary or binary_compressed, any
// numeric field types, organized or not) and fills what the file has:
//   intensity  from "intensity" (any numeric type)
//   ring       from "ring" (any integer type; other names such as "channel" are not rings
//              in every vendor's numbering, so they are not used)
//   time       from "time": integer types are ns since the epoch, floating-point types
//              seconds (the convention of many ROS tools)
// Missing fields read as 0. Points with a non-finite x, y or z (the placeholders of organized
// clouds) are left out.

#include <cstdint>
#include <filesystem>
#include <span>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "station/io/input_budget.h"
#include "station/sensors/lidar/lidar_point.h"

namespace linecal {

enum class PcdEncoding { kAscii, kBinary, kBinaryCompressed };

struct PcdCloud {
  std::vector<LidarPoint> points;
  bool has_intensity = false;
  bool has_ring = false;
  bool has_time = false;
  std::int64_t non_finite_dropped = 0;  // points left out for a non-finite x, y or z
};

// Reads a PCD file. NotFound when the file does not exist; InvalidArgument "<path>: ..." when
// it is not a readable PCD file, lacks x/y/z, or a field has a count other than 1 or an
// unknown type. Never crashes on any file content. Cost: one read of the file; memory about
// twice its decoded size.
absl::StatusOr<PcdCloud> ReadPcd(const std::filesystem::path& path);

// ReadPcd under a budget (station/io/input_budget.h), checked from the header before anything
// is allocated: the file's bytes (stat), POINTS against budget.max_scan_points, and POINTS x
// point size against budget.max_file_bytes; OverBudget's InvalidArgument names the file. A
// body shorter than the header claims is refused as always ("... do not fit the file's N
// bytes of data"). Memory: at most about twice budget.max_file_bytes plus 32 bytes a point.
absl::StatusOr<PcdCloud> ReadPcd(const std::filesystem::path& path, const InputBudget& budget);

// Writes points as a PCD file with the fields above (an unorganized cloud: HEIGHT 1),
// replacing the file. Internal naming the path on failure. Cost: O(points); PCL's writer
// holds one copy of the data.
absl::Status WritePcd(const std::filesystem::path& path, std::span<const LidarPoint> points,
                      PcdEncoding encoding = PcdEncoding::kBinary);

}  // namespace linecal
