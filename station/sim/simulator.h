#pragma once
// The station simulator: one car in one station, every sensor rendered, written as a capture
// with a separate ground-truth file (docs/simulator.md).
//
// The car's true sensor mounting is the car model's nominal mounting plus a random error,
// uniform within ±perturb bounds per mounting angle and per axis of the position; the car's
// pose in the station is a random aligner measurement within its bounds. Cameras are rendered
// by camera_render.h, LiDARs ray-cast by lidar_sim.h (PCD scans and vendor pcap), radars by
// radar_sim.h (candump log). Deterministic for a seed: every sensor draws from its own stream
// (seed, sensor index), so adding a sensor does not change the others.

#include <atomic>
#include <cstdint>
#include <functional>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "station/capture/capture.h"
#include "station/model/car_model.h"
#include "station/model/station_layout.h"
#include "station/sim/camera_render.h"
#include "station/sim/lidar_sim.h"
#include "station/sim/radar_sim.h"

namespace linecal {

inline constexpr char kGroundTruthFormat[] = "linecal.ground_truth";
inline constexpr int kGroundTruthVersion = 1;

// A board standing away from where the station file surveyed it (a knocked board or stand):
// the simulator renders and scans it at T_station_board = (R_move * R_surveyed,
// t_surveyed + offset_m), R_move = Rz(yaw) * Ry(pitch) * Rx(roll) about the page centre in
// station axes, while the capture keeps the surveyed station, so the calibration solves
// against where the board should be, as on a real line (docs/simulator.md).
struct MovedBoard {
  std::string board_id;
  double yaw_deg = 0, pitch_deg = 0, roll_deg = 0;
  Eigen::Vector3d offset_m = Eigen::Vector3d::Zero();
};

struct SimulatorOptions {
  std::string vin = "1M8GDM9AXKP042788";
  // Capture time, ns since the epoch. A fixed default keeps captures reproducible.
  std::int64_t time_ns = 1763776000000000000;
  // Mounting error bounds: uniform in ±these per angle and per position axis.
  double perturb_angle_deg = 0.5;
  double perturb_offset_m = 0.01;
  // Aligner bounds: longitudinal and lateral offsets and thrust angle, uniform in ±these.
  double aligner_offset_m = 0.02;
  double aligner_thrust_deg = 0.2;
  // The aligner's measurement to use instead of a random one (a daemon cycle simulating the
  // car the station controller described).
  std::optional<AlignerMeasurement> aligner;
  int camera_frames = 1;  // frames per camera, 1..100
  CameraRenderOptions camera;
  LidarSimOptions lidar;
  bool lidar_pcd = true;   // write one PCD per rotation
  bool lidar_pcap = true;  // write the vendor packets
  RadarSimOptions radar;
  // Boards standing moved (each id at most once, a board of the station; angles within
  // +-10 degrees and offsets within +-0.5 m: more is another station, not a moved board).
  std::vector<MovedBoard> moved_boards;
  // Only these sensors (empty: all of the car model).
  std::vector<std::string> sensors;
  // The true mounting T_car_sensor of these sensors (by name, each a sensor of the car)
  // instead of the random one: an evaluation that draws its own truth. The random draws are
  // still made, so every other sensor's stream stays as it was.
  std::map<std::string, Rigid3d> true_mountings;
  // When set and true, the simulation stops before its next sensor with Cancelled (a daemon
  // cycle cancelled or draining: one sensor's frames at most are still made, not the car's).
  const std::atomic<bool>* cancel = nullptr;
  // OK or InvalidArgument naming the first bad field (nested options included). O(1).
  absl::Status Validate() const;
};

// Called after each sensor: (sensors done, sensors in all, the sensor's name).
using SimulatorProgress = std::function<void(int, int, const std::string&)>;

struct SimulationSummary {
  CaptureManifest manifest;
  nlohmann::json ground_truth;
};

// Simulates the car in the station and writes the capture into `out_dir` (created if
// missing; existing files of the same names are replaced). Errors: InvalidArgument for bad
// options, a sensor name the car does not have, a moved board the station does not have,
// or a car whose targets are not in the station; Internal for files that cannot be written (naming
// them); Cancelled once options.cancel is true (checked before each sensor). Cost: dominated by the
// camera renders (about 0.2 s per 1920x1080 frame) and LiDAR rotations.
absl::StatusOr<SimulationSummary> SimulateCapture(const StationLayout& station, const CarModel& car,
                                                  const SimulatorOptions& options,
                                                  std::uint64_t seed, const std::string& out_dir,
                                                  const SimulatorProgress& progress = nullptr);

}  // namespace linecal
