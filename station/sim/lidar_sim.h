#pragma once
// The station simulator's LiDAR: ray casting of a spinning LiDAR's real beam pattern against
// a station (docs/simulator.md, "LiDAR simulator").
//
// Every column (one firing of all channels) casts one ray per beam, in the direction the
// decoders will assign to that return (BeamAzimuthRad, the model's column step and timing), so
// that the simulated packets decode to exactly the simulated points. A ray returns from the
// nearest of: the printed face or back of a board — except where the board has a through
// hole or ends (PaintAt says kHole / kOffBoard), where it flies on —, a board's stand (a
// vertical post from the floor to an upright board's lower edge), a surface (wall), or the
// floor z = 0; beyond the model's range, or with a dropout, there is no return. Ranges get
// Gaussian noise and are rounded to the packet's distance unit; intensity is the surface's
// reflectivity on the 0..255 calibrated-reflectivity scale of these sensors.
//
// Frames: T_station_lidar maps the vendor LiDAR frame (station/sensors/lidar/lidar_format.h) into
// the station frame; points are in the LiDAR frame, metres.

#include <cstdint>
#include <vector>

#include "absl/status/statusor.h"
#include "detectors/core/pose.h"
#include "station/model/car_model.h"
#include "station/model/station_layout.h"
#include "station/sensors/lidar/lidar_format.h"
#include "station/sensors/lidar/lidar_point.h"

namespace linecal {

struct LidarSimOptions {
  int rotations = 1;                 // full rotations to simulate, 1..100
  double range_sigma_m = 0.02;       // Gaussian range noise, [0, 1] (docs/acceptance.md: 1-3 cm)
  double dropout_probability = 0.0;  // a return is lost with this probability, [0, 1)
  double min_range_m = 0.3;          // the sensors see nothing nearer (their own window)
  double max_range_m = 120.0;        // and nothing beyond (station walls are far closer)
  // Board print reflectivity (0..1): white paper and black ink as the LiDAR sees them.
  double white_reflectivity = 0.8;
  double black_reflectivity = 0.08;
  double board_back_reflectivity = 0.4;
  double stand_reflectivity = 0.3;
  double stand_radius_m = 0.03;  // a 6 cm post
  // A free-running motor (a real sensor's is not locked to the scan): every rotation's firing
  // grid starts at its own azimuth phase, uniform over the whole centidegrees of one column
  // step (0.2 deg: 20 phases), drawn from the seed. Off: every rotation fires at the same
  // azimuths, the first column at azimuth 0 (a phase-locked sensor).
  bool free_running = false;
  // OK or InvalidArgument naming the first bad field. O(1).
  absl::Status Validate() const;
};

struct LidarSimResult {
  // options.rotations full rotations (rotation numbers 1, 2, ...), as the decoders assemble
  // them: every point in the rotation its own corrected azimuth falls in, in firing order,
  // range already rounded to the distance unit.
  std::vector<LidarScan> scans;
  // Every column fired, in order, for EncodeLidarPackets (single return): the rotations plus
  // a lead-in before azimuth 0 and a lead-out after the last rotation (kLidarLeadDeg each,
  // whole packets), so that a decoder sees every rotation start and end.
  std::vector<LidarColumn> columns;
  LidarEncodeSettings encode;  // first_column_time_ns is the time of columns[0]
};

// The lead-in and lead-out around the simulated rotations, degrees: more than the largest
// Hesai azimuth offset (5.2 degrees in the reference Pandar64 file), so that every beam of the
// first and last rotation is fired, and whole packets.
inline constexpr double kLidarLeadDeg = 10.0;

// The azimuth step between columns used by the simulator, in 0.01 degree: 0.2° for the
// VLP-16 and Pandar64, 0.18° for the PandarXT-32 — whole centidegrees close to each model's
// column period at 10 Hz, so every column's azimuth is exact in the packets.
int SimulatedColumnStepCentideg(LidarModel model);

// Casts `options.rotations` rotations, the first starting at azimuth 0 at time `start_time_ns`
// (the lead-in fires before it). With options.free_running, rotation r's columns (the lead-in
// with the first, the lead-out with the last) fire at their azimuths plus rotation r's phase.
// The phase changes only where a rotation starts, a packet boundary for every model (a
// rotation is a whole number of packets), and the VLP-16 decoder interpolates a block's second
// firing from the next block of its own packet only: every point decodes to the azimuth its
// ray was cast at, per-laser firing delays included (tests/station/sim/lidar_radar_sim_test.cc,
// FreeRunningPacketsDecodeToTheAzimuthsOfTheRaysCast).
// Deterministic for a seed. Errors: InvalidArgument for invalid options or beam table.
// Cost: rotations · columns · beams ray casts against every board, surface and stand
// (about 40 ms for a Pandar64 rotation in the reference station).
absl::StatusOr<LidarSimResult> SimulateLidar(const LidarBeamTable& beams,
                                             const Rigid3d& T_station_lidar,
                                             const StationLayout& layout,
                                             const LidarSimOptions& options,
                                             std::int64_t start_time_ns, std::uint64_t seed);

}  // namespace linecal
