#pragma once
// What a radar can see: the field of view and range of each supported model (data sheets), and
// the station's corner reflectors as a radar at a given pose sees them. Facts of the sensor
// and the layout, shared by the solvers (which reflectors to expect), the planner and the
// simulator (docs/lidar-radar.md).

#include <optional>
#include <string>
#include <vector>

#include "detectors/core/pose.h"
#include "station/model/station_layout.h"

namespace linecal {

// Field of view of a radar model: detections outside |azimuth| <= half_fov_rad or beyond
// max_range_m are not reported.
struct RadarFieldOfView {
  double half_fov_rad = 0;
  double max_range_m = 0;
};
// "ars408": the near scan (±60°, 70 m) that covers station distances; "esr": the mid-range
// scan (±45°, 60 m). nullopt for other names.
std::optional<RadarFieldOfView> RadarFieldOfViewOf(const std::string& model);

// One reflector as the radar truly sees it (ground truth).
struct RadarTruth {
  std::string reflector_id;
  double range_m = 0;
  double azimuth_rad = 0;
  bool in_view = false;  // inside the field of view and range
};

// The reflectors of `layout` seen from a radar at T_station_radar: exact range and azimuth
// (the radar frame's x-y plane; a reflector above or below counts by its horizontal
// projection's direction and its 3-D range). O(reflectors).
std::vector<RadarTruth> RadarReflectorTruth(const StationLayout& layout,
                                            const Rigid3d& T_station_radar,
                                            const RadarFieldOfView& fov);

}  // namespace linecal
