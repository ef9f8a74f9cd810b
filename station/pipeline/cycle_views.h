#pragma once
// What the console's cycle page draws over a cycle's recorded data (docs/console.md, "Cycle
// views"). The store keeps each sensor's result, not its features, so a view is recomputed
// from the cycle's capture with the cycle's own code (DetectCameraFrame, CalibrateLidarFrames,
// CalibrateRadar): the same capture gives the same features the cycle used.
//   camera  one frame: each target board's detected features, and every board feature where
//           the mounting (the stored result's, else the nominal one) and the capture's aligner
//           put it (the reprojected board)
//   lidar   every rotation's points from above (sensor frame x, y) within the boards' area,
//           at most kMaxViewPoints; each target board as fitted (outline, hole centres) and
//           where the nominal mounting expects it
//   radar   the detections of the cycles the calibration used (sensor frame x, y), at most
//           kMaxViewPoints; each reflector where the nominal mounting expects it, as found
//           (the mean of its detections) and where the solved yaw predicts it
// Numbers are metres and pixels; points are [x, y] arrays (features [id, u, v]) to keep a
// view of 20,000 points near 400 kB.

#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "station/capture/capture.h"

namespace linecal {

// Points of a LiDAR view and detections of a radar view, at most: the page draws them as one
// SVG path, and 20,000 keep the board's outline readable at a few mm a point.
inline constexpr int kMaxViewPoints = 20000;

// One file of a capture, as the console lists it for download.
struct CaptureFileEntry {
  std::string path;    // inside the capture, as the manifest has it
  std::string sensor;  // empty for the capture's own files
  std::string role;    // "manifest", "station", "car", "frame", "scan", "packets", "can_log"
};

// manifest.json, station.json, car.json, then every sensor's files in manifest order. The
// console addresses a file by its index in this list, never by a path from the client. Pure.
std::vector<CaptureFileEntry> CaptureFileList(const Capture& capture);

// The view of `sensor` of `capture` (see above). `frame` picks a camera's frame (0-based;
// ignored for LiDARs and radars, which use every rotation and the whole CAN log as the cycle
// did); `T_car_sensor` is the cycle's solved mounting (16 values, row-major; empty: draw
// with the nominal one). NotFound when the capture has no such sensor; InvalidArgument for
// a frame out of range; a data file that cannot be read gives its reader's error. Cost: one
// frame's detection (cameras), the LiDAR board fit, or the radar's decode and association.
absl::StatusOr<nlohmann::json> SensorViewJson(const Capture& capture, const std::string& sensor,
                                              int frame, const std::vector<double>& T_car_sensor);

}  // namespace linecal
