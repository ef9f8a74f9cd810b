#pragma once
// LiDAR-to-car calibration from round-hole boards: the hole centres (and board normals) a
// LiDAR measured, matched to where the station layout and the aligner put them in the car
// frame (p_car = T_car_station * T_station_board * p_board), solved for T_car_lidar.
//
// Method: a weighted closed-form start (Kabsch/Umeyama without scale on the hole centres),
// then Ceres on the hole-centre residuals and, where given, the board-normal residuals, with
// an optional box bound on the translation around the nominal mounting (the install
// tolerance: a LiDAR cannot be mounted 20 cm off, so such a solution is a wrong match). The
// covariance is (JᵀJ)⁻¹ of the whitened residuals at the solution (feature sigmas are
// inputs, from the detector's fit), moved to yaw/pitch/roll and position (mounting.h).
//
// Verdicts: as cameras (mounting.h), with errors "board_not_found", "too_few_features" (fewer
// than 3 hole centres, or all on one line), "residual_too_high" (hole centres that no rigid
// motion brings onto the layout: a moved board or a wrong match), "uncertainty_too_high".

#include <Eigen/Core>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "absl/status/statusor.h"
#include "detectors/core/pose.h"
#include "detectors/round_hole/round_hole_cloud.h"
#include "station/model/car_model.h"
#include "station/model/station_layout.h"
#include "station/solvers/mounting.h"

namespace linecal {

struct LidarHoleCentre {
  int feature_id = 0;                                 // the board's hole-centre feature id
  Eigen::Vector3d p_lidar = Eigen::Vector3d::Zero();  // metres, LiDAR frame
};

// One board as the LiDAR measured it (several frames already accumulated by the detector).
struct LidarBoardObservation {
  std::string board_id;  // a round-hole board of the station layout
  std::vector<LidarHoleCentre> holes;
  // The board's +z (out of the print) in the LiDAR frame, unit; nullopt: not used.
  std::optional<Eigen::Vector3d> normal_lidar;
  // Per-axis 1-sigma of this board's hole centres (metres) and of its normal (radians); 0:
  // the options' defaults.
  double centre_sigma_m = 0;
  double normal_sigma_rad = 0;
  // The board's pose as the detector measured it, with the covariance of its error in the
  // board frame (T_true = T_lidar_board * (R(theta), t), order theta_x, theta_y, theta_z,
  // t_x, t_y, t_z: RoundHoleCloudDetection::pose_covariance). When set, the board enters the
  // solve as one pose residual whitened by that covariance instead of its hole centres and
  // normal, so that the errors its five centres share (and the board's in-plane rotation)
  // count once, as the detector measured them; the centres still give the start and the
  // residual check. Must be symmetric positive definite.
  std::optional<Rigid3d> T_lidar_board;
  Eigen::Matrix<double, 6, 6> pose_covariance = Eigen::Matrix<double, 6, 6>::Zero();
};

// The observation of a found round-hole detection: its pose with the detector's 6x6
// covariance (what the solve uses), its hole centres and normal with their sigmas (for the
// closed-form start and the residual check; 1 mm is the floor below which the fit's own
// sigma is not trusted). One conversion for the cycle (station/pipeline) and the planner's
// prediction (station/planner). O(holes).
LidarBoardObservation LidarObservationFromDetection(const std::string& board_id,
                                                    const RoundHoleCloudDetection& detection);

struct LidarCalibrationOptions {
  // Default per-axis hole-centre sigma, metres: what the detector reaches with 16 rings.
  // (0, 1].
  double centre_sigma_m = 0.005;
  // Default board-normal sigma, radians (0.1°, the detector's bar). (0, 1].
  double normal_sigma_rad = 0.1 * 3.14159265358979323846 / 180.0;
  // > 0: each translation component stays within ± this of the nominal mounting, metres;
  // 0: unbounded. [0, 10].
  double translation_bound_m = 0;
  // The RMS hole-centre residual above which the match is refused (residual_too_high),
  // metres: 3 cm is six times the 16-ring sigma, far below the 60 cm hole pitch a wrong
  // match is off by. (0, 1].
  double max_residual_rms_m = 0.03;
  // As for cameras (camera_calibration.h). (0, 10].
  double max_sigma_fraction_of_tolerance = 1.0 / 3.0;

  // Empty when valid, else the name of the first field out of range.
  std::string_view Validate() const;
};

struct LidarCalibrationResult {
  Verdict verdict = Verdict::kError;
  std::string reason;
  std::string message;
  bool solved = false;
  MountingEstimate mounting;
  double residual_rms_m = 0;  // RMS of the hole-centre residual lengths after the solve
  int features_used = 0;      // hole centres
  int boards_used = 0;
  // When solved: each board's hole-centre RMS (metres), in observation order.
  std::vector<BoardResidual> board_residuals;
  bool translation_at_bound = false;  // a bound is active: the sigma of that axis is optimistic
};

// Calibrates `sensor` (a LiDAR of the car model). Errors (InvalidArgument): not a LiDAR,
// invalid options, an observation of a board not in `station`, an unknown hole feature id,
// non-finite input. Everything else is an outcome in the result. Cost: one small Ceres solve
// (about 0.1 ms for 10 hole centres).
absl::StatusOr<LidarCalibrationResult> CalibrateLidar(
    const SensorModel& sensor, const StationLayout& station, const Rigid3d& T_station_car,
    std::span<const LidarBoardObservation> observations,
    const LidarCalibrationOptions& options = {});

}  // namespace linecal
