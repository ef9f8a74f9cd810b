#pragma once
// The station simulator's radar: what an ARS408 or Delphi ESR reports of a station's corner
// reflectors and clutter over a number of measurement cycles, as the CAN frames the sensor
// sends (docs/simulator.md, "Radar simulator").
//
// Every reflector of the layout inside the radar's field of view and range gives one
// detection per cycle with Gaussian range, azimuth and RCS noise and zero range rate (the
// car stands still). Clutter adds weak detections at random places, some moving; multipath
// adds a weaker ghost of a reflector at a longer range. Elevation is not modelled: these
// radars report none.

#include <cstdint>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "detectors/core/pose.h"
#include "station/io/candump.h"
#include "station/model/station_layout.h"
#include "station/sensors/radar/field_of_view.h"
#include "station/sensors/radar/radar_format.h"

namespace linecal {

struct RadarSimOptions {
  int cycles = 20;                      // measurement cycles to simulate, 1..10000
  double range_sigma_m = 0.05;          // per-detection range noise, [0, 5]
  double azimuth_sigma_deg = 0.1;       // per-detection azimuth noise, [0, 10] (docs/acceptance.md)
  double rcs_sigma_db = 1.0;            // per-detection RCS noise, [0, 20]
  double range_rate_sigma_mps = 0.03;   // noise on the (zero) range rate of static targets, [0, 5]
  double detection_probability = 0.98;  // a reflector is reported in a cycle with this, (0, 1]
  int clutter_per_cycle = 6;            // weak random detections per cycle, 0..200
  bool multipath = true;                // a ghost of each reflector at 1.3..1.8 x its range
  // OK or InvalidArgument naming the first bad field. O(1).
  absl::Status Validate() const;
};

// Simulates `options.cycles` cycles of the radar `model` ("ars408" with `sensor_id`, or "esr")
// starting at `start`, and returns the CAN frames it sends on `interface`, in time order.
// ARS408: cluster lists every 72 ms; ESR: track scans every 50 ms (the sensors' cycle times).
// Deterministic for a seed. Errors: InvalidArgument for bad options or an unknown model.
absl::StatusOr<std::vector<CanFrame>> SimulateRadar(const std::string& model, int sensor_id,
                                                    const StationLayout& layout,
                                                    const Rigid3d& T_station_radar, CanTime start,
                                                    const std::string& interface,
                                                    const RadarSimOptions& options,
                                                    std::uint64_t seed);

}  // namespace linecal
