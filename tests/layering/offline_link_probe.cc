// Linked against the libraries behind `linecal calibrate` and `linecal lidar decode` only
// (station/pipeline, station/sensors): check_offline_links.cmake reads this program's
// DT_NEEDED entries, which list every shared library those libraries' link interfaces pull
// in, and fails on Aravis, gRPC or SQLite (docs/conventions.md, "Map of the tree").
#include "station/pipeline/capture_calibration.h"
#include "station/sensors/lidar/lidar_decoder.h"

int main() {
  // Take the entry points' addresses (volatile: kept) so the objects behind them are linked.
  const void* volatile entry_points[] = {
      reinterpret_cast<const void*>(&linecal::CalibrateCapture),
      reinterpret_cast<const void*>(&linecal::LidarDecoder::Create)};
  return entry_points[0] != nullptr && entry_points[1] != nullptr ? 0 : 1;
}
