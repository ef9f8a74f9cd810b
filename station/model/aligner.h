#pragma once
// The four-wheel aligner's measurement of one car: where the car stands in the station.

#include <nlohmann/json.hpp>

#include "absl/status/statusor.h"
#include "detectors/core/pose.h"
#include "station/io/json_reader.h"

namespace linecal {

struct AlignerMeasurement {
  double longitudinal_offset_m = 0.0;  // car origin along x_station
  double lateral_offset_m = 0.0;       // car origin along y_station (left positive)
  double thrust_angle_rad = 0.0;       // car x axis vs station x axis, about z (left positive)

  // T_station_car = Translation(longitudinal, lateral, 0) * Rz(thrust): the car stays on the
  // floor (z = 0) and only turns about the vertical.
  Rigid3d T_station_car() const;
};

// Reads {"longitudinal_offset_m": .., "lateral_offset_m": .., "thrust_angle_deg": ..} at
// parent.key. Offsets beyond +-1 m or thrust beyond +-10 degrees are rejected: the aligner
// centres the car to a few centimetres, so such values mean a wrong unit or a bad reading.
absl::StatusOr<AlignerMeasurement> ReadAligner(const JsonField& parent, const std::string& key);
nlohmann::json AlignerToJson(const AlignerMeasurement& a);

}  // namespace linecal
