#include "station/sensors/radar/field_of_view.h"

#include <cmath>
#include <numbers>

namespace linecal {
namespace {

constexpr double kDegToRad = std::numbers::pi / 180.0;

}  // namespace

std::optional<RadarFieldOfView> RadarFieldOfViewOf(const std::string& model) {
  if (model == "ars408") return RadarFieldOfView{60 * kDegToRad, 70.0};
  if (model == "esr") return RadarFieldOfView{45 * kDegToRad, 60.0};
  return std::nullopt;
}

std::vector<RadarTruth> RadarReflectorTruth(const StationLayout& layout,
                                            const Rigid3d& T_station_radar,
                                            const RadarFieldOfView& fov) {
  const Rigid3d T_radar_station = T_station_radar.Inverse();
  std::vector<RadarTruth> out;
  for (const CornerReflector& r : layout.reflectors) {
    const Eigen::Vector3d p_radar = T_radar_station * r.p_station;
    RadarTruth t;
    t.reflector_id = r.id;
    t.range_m = p_radar.norm();
    t.azimuth_rad = std::atan2(p_radar.y(), p_radar.x());
    t.in_view = p_radar.x() > 0 && std::abs(t.azimuth_rad) <= fov.half_fov_rad &&
                t.range_m <= fov.max_range_m;
    out.push_back(t);
  }
  return out;
}

}  // namespace linecal
