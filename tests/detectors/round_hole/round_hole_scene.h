#pragma once
// Simulated LiDAR scenes of round-hole boards for the cloud detector's tests: the station
// simulator scans boards (with their stands and the floor) and optional surfaces with the
// reference car's beam tables.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <string>
#include <vector>

#include "detectors/round_hole/round_hole_cloud.h"
#include "station/model/car_model.h"
#include "station/model/pose_json.h"
#include "station/model/station_layout.h"
#include "station/sensors/lidar/lidar_format.h"
#include "station/sim/lidar_sim.h"
#include "tests/detectors/board_scene.h"

namespace linecal {

inline constexpr double kDegToRad = std::numbers::pi / 180.0;
inline const std::string kDeploy = std::string(LINECAL_SOURCE_DIR) + "/deploy";
// The LiDAR and the board centre sit this high above the floor: the floor stays well below
// the board, whose lowest rings would otherwise hit it just behind the page.
inline constexpr double kHeightM = 1.0;

// "roof_lidar" (Pandar64, deploy/cars/Pandar64.csv) or "bumper_lidar" (VLP-16, built in).
inline LidarBeamTable Beams(const std::string& sensor) {
  const CarModel car = *ReadCarModel(kDeploy + "/cars/reference.json");
  return *LidarBeamTableOf(*car.FindSensor(sensor));
}

// One scene of the accuracy tests: a LiDAR of the reference car (by sensor name), the board
// at a distance and bearing from it, turned by a heading, scanned with range noise sigma_m.
struct Case {
  const char* sensor;
  double distance_m;
  double bearing_deg;
  double heading_deg;
  double sigma_m;
  double bar_m;  // docs/acceptance.md: 1 cm for 64 rings, 2 cm for 16 rings (10 frames)
};

struct Scene {
  Board board;
  Rigid3d T_lidar_board;  // truth (of the first board)
  std::vector<std::vector<RoundHoleCloudPoint>> frames;
};

// The pose in the station of something `distance_m` from the LiDAR (which stands at the
// station origin, kHeightM up, azimuth 0 along +x) along `bearing_deg`, turned by
// `heading_deg` about the vertical from facing the LiDAR, its centre `lift_m` above the LiDAR.
inline Rigid3d FacingPose(double distance_m, double bearing_deg, double heading_deg,
                          double lift_m = 0.0) {
  const double bearing = bearing_deg * kDegToRad;
  const Eigen::Matrix3d R =
      Eigen::AngleAxisd(bearing + heading_deg * kDegToRad, Eigen::Vector3d::UnitZ())
          .toRotationMatrix() *
      BoardBaseRotation();
  return Rigid3d(R, Eigen::Vector3d(distance_m * std::cos(bearing), distance_m * std::sin(bearing),
                                    kHeightM + lift_m));
}

inline StationBoard RoundHoleAt(const Rigid3d& T_station_board, double scale = 1.0,
                                const std::string& id = "board") {
  StationBoard b;
  b.id = id;
  b.params.type = BoardType::kRoundHole;
  b.params.scale = scale;
  b.board = *Board::Create(b.params);
  b.T_station_board = T_station_board;
  return b;
}

// Scans `layout` (its first board is the scene's truth) for `rotations` rotations, each at its
// own azimuth phase when `free_running` (LidarSimOptions::free_running).
inline Scene SimulateLayout(const LidarBeamTable& beams, const StationLayout& layout,
                            double sigma_m, int rotations, std::uint64_t seed = 1,
                            bool free_running = false) {
  const Rigid3d T_station_lidar(LidarBaseRotation(), Eigen::Vector3d(0, 0, kHeightM));
  LidarSimOptions o;
  o.rotations = rotations;
  o.range_sigma_m = sigma_m;
  o.free_running = free_running;
  absl::StatusOr<LidarSimResult> sim = SimulateLidar(beams, T_station_lidar, layout, o, 0, seed);
  EXPECT_TRUE(sim.ok()) << sim.status();
  const StationBoard& b = layout.boards.front();
  Scene scene{b.board, T_station_lidar.Inverse() * b.T_station_board, {}};
  if (!sim.ok()) return scene;
  for (const LidarScan& scan : sim->scans) {
    std::vector<RoundHoleCloudPoint>& f = scene.frames.emplace_back();
    for (const LidarPoint& p : scan.points) f.push_back({p.x, p.y, p.z, p.ring});
  }
  return scene;
}

// A station with one round-hole board (FacingPose), scanned for `rotations` rotations.
inline Scene Simulate(const LidarBeamTable& beams, double distance_m, double bearing_deg,
                      double heading_deg, double sigma_m, int rotations, double scale = 1.0,
                      double lift_m = 0.0) {
  StationLayout layout;
  layout.name = "round_hole_test";
  layout.boards.push_back(
      RoundHoleAt(FacingPose(distance_m, bearing_deg, heading_deg, lift_m), scale));
  return SimulateLayout(beams, layout, sigma_m, rotations);
}

// A surface `size_m` wide and high whose centre is at `centre_station`, facing along the
// horizontal direction `facing_rad` (station frame).
inline StationSurface Panel(const std::string& id, const Eigen::Vector3d& centre_station,
                            double facing_rad, Eigen::Vector2d size_m) {
  StationSurface s;
  s.id = id;
  // The surface's x-y plane is the rectangle: x horizontal, y up, z its normal.
  const Eigen::Vector3d z(std::cos(facing_rad), std::sin(facing_rad), 0.0);
  const Eigen::Vector3d y = Eigen::Vector3d::UnitZ();
  Eigen::Matrix3d R;
  R << y.cross(z), y, z;
  s.T_station_surface = Rigid3d(R, centre_station);
  s.size_m = size_m;
  s.reflectivity = 0.5;
  return s;
}

// A box of the board's size (1.1 m cube) standing on the floor, centred `distance_m` along
// `bearing_deg` from the LiDAR: its four sides and its top.
inline void AddBox(StationLayout& layout, double distance_m, double bearing_deg) {
  const double b = bearing_deg * kDegToRad;
  const Eigen::Vector3d c(distance_m * std::cos(b), distance_m * std::sin(b), 0.55);
  const Eigen::Vector2d side(1.1, 1.1);
  for (int k = 0; k < 4; ++k) {
    const double facing = b + k * 0.5 * std::numbers::pi;
    layout.surfaces.push_back(
        Panel("box_side" + std::to_string(k),
              c + 0.55 * Eigen::Vector3d(std::cos(facing), std::sin(facing), 0), facing, side));
  }
  StationSurface top;
  top.id = "box_top";
  top.T_station_surface = Rigid3d::Translation(c + Eigen::Vector3d(0, 0, 0.55));
  top.size_m = side;
  layout.surfaces.push_back(top);
}

// The search's scene of case `c`: the board on its stand, a wall 2 m behind it facing the
// LiDAR, and a board-sized box 90 degrees around (round_hole_search_test.cc and
// round_hole_bench.cc).
inline StationLayout BoardWallAndBox(const Case& c) {
  StationLayout layout;
  layout.name = "search_test";
  layout.boards.push_back(RoundHoleAt(FacingPose(c.distance_m, c.bearing_deg, c.heading_deg)));
  const double b = c.bearing_deg * kDegToRad;
  layout.surfaces.push_back(Panel(
      "wall",
      Eigen::Vector3d((c.distance_m + 2) * std::cos(b), (c.distance_m + 2) * std::sin(b), 1.5),
      b + std::numbers::pi, Eigen::Vector2d(8.0, 3.0)));
  AddBox(layout, c.distance_m, c.bearing_deg + 90.0);
  return layout;
}

// The largest distance of the detected hole centres from their true positions, metres.
inline double WorstHoleError(const Scene& scene, const RoundHoleCloudDetection& d) {
  double worst = 0.0;
  for (const RoundHoleHole& h : d.holes) {
    const Eigen::Vector2d p_board = scene.board.features()[h.id].p_board;
    const Eigen::Vector3d truth =
        scene.T_lidar_board * Eigen::Vector3d(p_board.x(), p_board.y(), 0.0);
    worst = std::max(worst, (h.p_lidar - truth).norm());
  }
  return worst;
}

// Runs detect(views) on the scene's frames and returns its result, with the thread CPU time
// per frame in *ms_per_frame when given (the bar is the detector's cost, not the shared
// machine's load).
template <typename Detect>
auto TimedPerFrame(const Scene& scene, double* ms_per_frame, Detect&& detect) {
  const std::vector<std::span<const RoundHoleCloudPoint>> views(scene.frames.begin(),
                                                                scene.frames.end());
  const double start_ms = test_scene::ThreadCpuMs();
  auto result = detect(std::span<const std::span<const RoundHoleCloudPoint>>(views));
  const double elapsed_ms = test_scene::ThreadCpuMs() - start_ms;
  if (ms_per_frame != nullptr) *ms_per_frame = elapsed_ms / std::max<std::size_t>(views.size(), 1);
  return result;
}

}  // namespace linecal
