#include "station/solvers/camera_calibration.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <numbers>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"

namespace linecal {
namespace {

// Root mean square of `values`; 0 for none. O(n).
double Rms(const std::vector<double>& values) {
  double sum_sq = 0;
  for (double v : values) sum_sq += v * v;
  return values.empty() ? 0.0 : std::sqrt(sum_sq / static_cast<double>(values.size()));
}

// All features of the observed board of `type` with the most of them, frames pooled, and
// that board's id; empty when none was seen.
std::pair<std::string, std::vector<DetectedFeature>> MostSeenBoard(
    const StationLayout& station, std::span<const BoardObservation> observations, BoardType type) {
  std::map<std::string, std::vector<DetectedFeature>> pooled;
  for (const BoardObservation& o : observations) {
    const StationBoard* board = station.FindBoard(o.board_id);
    if (board == nullptr || board->board.type() != type) continue;
    std::vector<DetectedFeature>& all = pooled[o.board_id];
    all.insert(all.end(), o.features.begin(), o.features.end());
  }
  std::pair<std::string, std::vector<DetectedFeature>> best;
  for (auto& [id, features] : pooled) {
    if (features.size() > best.second.size()) best = {id, std::move(features)};
  }
  return best;
}

}  // namespace

absl::Status CameraCalibrationOptions::Validate() const {
  if (const std::string_view bad = pnp.Validate(); !bad.empty()) {
    return absl::InvalidArgumentError(absl::StrCat("pnp.", std::string(bad), " is out of range"));
  }
  if (min_features < 4 || min_features > 10000)
    return absl::InvalidArgumentError("min_features is outside [4, 10000]");
  if (!(max_residual_rms_px > 0 && max_residual_rms_px <= 100)) {
    return absl::InvalidArgumentError("max_residual_rms_px is outside (0, 100]");
  }
  if (!(max_sigma_fraction_of_tolerance > 0 && max_sigma_fraction_of_tolerance <= 10)) {
    return absl::InvalidArgumentError("max_sigma_fraction_of_tolerance is outside (0, 10]");
  }
  for (double d : ranging_distances_m) {
    if (!(d > 0 && d < 1e4))
      return absl::InvalidArgumentError(
          "ranging_distances_m: every distance must be in (0, 10000)");
  }
  return absl::OkStatus();
}

int CarAxisAlong(const Rigid3d& T_camera_car) {
  // The optical axis in the car frame; within 45 degrees of ±x_car the camera looks along
  // the car (front and rear cameras), beyond it sideways.
  const double axis_x = T_camera_car.RotationMatrix().row(2).x();
  constexpr double kCos45 = 0.70710678118654752;
  return axis_x >= kCos45 ? 1 : axis_x <= -kCos45 ? -1 : 0;
}

std::vector<RangingCheck> RangingCheckOf(const CameraModel& camera, const Rigid3d& T_camera_car,
                                         const Eigen::Vector2d& vanishing_point_px,
                                         std::span<const double> distances_m) {
  const Rigid3d T_car_camera = T_camera_car.Inverse();
  const Eigen::Vector3d c = T_car_camera.translation();
  const CameraIntrinsics& k = camera.intrinsics();
  const int along = CarAxisAlong(T_camera_car);
  std::vector<RangingCheck> out;
  for (double d : distances_m) {
    RangingCheck r{d, std::numeric_limits<double>::quiet_NaN()};
    const Eigen::Vector3d p_camera = T_camera_car * Eigen::Vector3d(c.x() + along * d, c.y(), 0.0);
    Eigen::Vector2d uv;
    // The point must really be in the image; its undistorted row is what the formula reads.
    if (along != 0 && p_camera.z() > 0 && camera.Project(p_camera, &uv) && camera.IsInImage(uv)) {
      const Eigen::Vector2d undistorted = (PinholeMatrix(k) * p_camera).hnormalized();
      r.measured_distance_m = FlatGroundRange(k, vanishing_point_px, c.z(), undistorted).x();
    }
    out.push_back(r);
  }
  return out;
}

bool CarAxisVanishingPoint(const CameraIntrinsics& intrinsics, const Rigid3d& T_camera_car,
                           Eigen::Vector2d* vanishing_point_px) {
  const int along = CarAxisAlong(T_camera_car);
  if (along == 0) return false;
  *vanishing_point_px =
      (PinholeMatrix(intrinsics) * (along * T_camera_car.RotationMatrix().col(0))).hnormalized();
  return true;
}

Eigen::Matrix3d GroundHomography(const CameraIntrinsics& intrinsics, const Rigid3d& T_camera_car) {
  const Eigen::Matrix3d R_camera_car = T_camera_car.RotationMatrix();
  Eigen::Matrix3d rt;
  rt << R_camera_car.col(0), R_camera_car.col(1), T_camera_car.translation();
  Eigen::Matrix3d h = PinholeMatrix(intrinsics) * rt;
  return h / h(2, 2);
}

namespace {

// The correspondences of the observed boards: every detection of every frame (with the
// index in boards_seen of its board), each feature's mean over the frames, and the boards
// seen (id, T_car_board) in first-seen order.
struct CameraInputs {
  std::vector<PnpCorrespondence> points;
  std::vector<size_t> point_board;
  std::vector<PnpCorrespondence> means;
  std::vector<std::pair<std::string, Rigid3d>> boards_seen;
};

// The correspondences of `observations` (boards of `station`, T_car_station from the
// aligner); InvalidArgument naming the sensor for a board not in the station.
absl::StatusOr<CameraInputs> CollectCorrespondences(
    const SensorModel& sensor, const StationLayout& station, const Rigid3d& T_car_station,
    std::span<const BoardObservation> observations) {
  CameraInputs in;
  // Per board feature, the sum of its detections over the frames and their count: frames of a
  // still scene repeat each feature (see `on_means` in CalibrateCamera).
  std::map<std::pair<std::string, int>, std::pair<PnpCorrespondence, int>> sums;
  for (const BoardObservation& o : observations) {
    const StationBoard* board = station.FindBoard(o.board_id);
    if (board == nullptr) {
      return absl::InvalidArgumentError(absl::StrCat(sensor.name, ": observed board '", o.board_id,
                                                     "' is not in station '", station.name, "'"));
    }
    if (o.features.empty()) continue;
    const Rigid3d T_car_board = T_car_station * board->T_station_board;
    size_t board_index = 0;
    while (board_index < in.boards_seen.size() && in.boards_seen[board_index].first != o.board_id)
      ++board_index;
    if (board_index == in.boards_seen.size()) in.boards_seen.emplace_back(o.board_id, T_car_board);
    // Each board its own rigid body and each board type (detector) its noise class: the
    // covariance gives every detector its own feature sigma (pnp.h).
    const int noise_class = static_cast<int>(board->board.type());
    for (const DetectedFeature& f : o.features) {
      in.points.push_back({T_car_board * Eigen::Vector3d(f.p_board.x(), f.p_board.y(), 0.0),
                           f.uv_px, static_cast<int>(board_index), noise_class, f.marker});
      in.point_board.push_back(board_index);
      auto& [sum, n] = sums[{o.board_id, f.id}];
      sum = {in.points.back().p_object, sum.uv_px + f.uv_px, static_cast<int>(board_index),
             noise_class, f.marker};
      ++n;
    }
  }
  for (const auto& [key, sum_n] : sums) {
    PnpCorrespondence mean = sum_n.first;
    mean.uv_px /= sum_n.second;
    in.means.push_back(mean);
  }
  return in;
}

// What the car's software derives from the extrinsic T_camera_car (valid whatever the
// verdict): the car axis's vanishing point, the ground homography and the ranging check.
void SetDerived(const CameraModel& camera, const SensorModel& sensor, const Rigid3d& T_camera_car,
                const CameraCalibrationOptions& options, CameraCalibrationResult* result) {
  result->vanishing_point_valid =
      CarAxisVanishingPoint(*sensor.intrinsics, T_camera_car, &result->vanishing_point_px);
  result->ground_homography = GroundHomography(*sensor.intrinsics, T_camera_car);
  if (result->vanishing_point_valid) {
    result->ranging = RangingCheckOf(camera, T_camera_car, result->vanishing_point_px,
                                     options.ranging_distances_m);
  }
}

// The seed formulas, cross-checking the extrinsic T_camera_car: the board method on the most
// seen wide chessboard (and its disagreement with the extrinsic's vanishing point and ground
// homography, which SetDerived gave) and the roll from the most seen vertical board; each
// with a reason when its board was not seen.
void SetSeedFormulas(const CameraModel& camera, const SensorModel& sensor,
                     const StationLayout& station, const Rigid3d& T_car_station,
                     std::span<const BoardObservation> observations,
                     const CameraCalibrationOptions& options, const Rigid3d& T_camera_car,
                     CameraCalibrationResult* result) {
  const Rigid3d T_car_camera = T_camera_car.Inverse();
  const int along = CarAxisAlong(T_camera_car);
  const auto [chessboard_id, chessboard] =
      MostSeenBoard(station, observations, BoardType::kChessboard);
  if (chessboard.empty()) {
    result->board_method.reason = "chessboard_not_seen";
    result->board_method.message =
        absl::StrCat(sensor.name, ": no wide chessboard among its observed boards");
  } else {
    const StationBoard& board = *station.FindBoard(chessboard_id);
    result->board_method =
        SolveBoardMethod(camera, board.board, T_car_station * board.T_station_board,
                         T_car_camera.translation(), along, chessboard);
    if (result->board_method.valid && result->vanishing_point_valid) {
      result->vanishing_point_disagreement_px =
          (result->board_method.vanishing_point_px - result->vanishing_point_px).norm();
      result->ground_disagreement =
          GroundDisagreement(result->ground_homography, result->board_method.ground_homography,
                             T_car_camera.translation(), along, options.ranging_distances_m);
      result->toolbox_ground_disagreement = GroundDisagreement(
          result->ground_homography, result->board_method.toolbox_ground_homography,
          T_car_camera.translation(), along, options.ranging_distances_m);
    }
  }
  const auto [vertical_id, vertical] = MostSeenBoard(station, observations, BoardType::kVertical);
  if (vertical.empty()) {
    result->vertical_roll.reason = "vertical_board_not_seen";
    result->vertical_roll.message =
        absl::StrCat(sensor.name, ": no vertical board among its observed boards");
  } else {
    const StationBoard& board = *station.FindBoard(vertical_id);
    result->vertical_roll =
        RollFromVerticalBoard(camera, board.board, T_car_station * board.T_station_board,
                              T_camera_car.RotationMatrix().col(0), vertical);
  }
}

// Each seen board's RMS reprojection error over its detections in every frame at the solved
// pose T_camera_car, in boards_seen order. O(points).
std::vector<BoardResidual> BoardResiduals(const CameraModel& camera, const CameraInputs& in,
                                          const Rigid3d& T_camera_car) {
  const std::vector<double> errors = ReprojectionErrors(camera, T_camera_car, in.points);
  std::vector<BoardResidual> out;
  for (const auto& [id, T_car_board] : in.boards_seen) out.push_back({id, 0.0, 0});
  for (size_t i = 0; i < errors.size(); ++i) {
    BoardResidual& b = out[in.point_board[i]];
    b.rms += errors[i] * errors[i];
    ++b.features;
  }
  for (BoardResidual& b : out) b.rms = std::sqrt(b.rms / std::max(b.features, 1));
  return out;
}

// Trust checks, then the tolerance: the verdict, reason and message of a solved result.
void Judge(const SensorModel& sensor, const CameraInputs& in, const Rigid3d& T_camera_car,
           const CameraCalibrationOptions& options, CameraCalibrationResult* result) {
  for (const auto& [id, T_car_board] : in.boards_seen) {
    if (!BoardFacesCamera(T_camera_car * T_car_board)) {
      result->reason = "board_seen_from_behind";
      result->message =
          absl::StrCat(sensor.name, ": the pose puts the print of board ", id,
                       " facing away from the camera (mirrored or mis-identified board)");
      return;
    }
  }
  if (result->residual_rms_px > options.max_residual_rms_px) {
    result->reason = "residual_too_high";
    result->message = absl::StrFormat(
        "%s: residual RMS %.3f px above %.3f px (moved board or wrong correspondence)", sensor.name,
        result->residual_rms_px, options.max_residual_rms_px);
    return;
  }
  const MountingJudgement judgement =
      JudgeMounting(sensor, result->mounting, options.max_sigma_fraction_of_tolerance);
  result->verdict = judgement.verdict;
  result->reason = judgement.reason;
  result->message = judgement.message;
}

}  // namespace

absl::StatusOr<CameraCalibrationResult> CalibrateCamera(
    const SensorModel& sensor, const StationLayout& station, const Rigid3d& T_station_car,
    std::span<const BoardObservation> observations, const CameraCalibrationOptions& options) {
  if (sensor.kind != SensorKind::kCamera || !sensor.intrinsics) {
    return absl::InvalidArgumentError(
        absl::StrCat("sensor ", sensor.name, " is not a camera with intrinsics"));
  }
  if (absl::Status s = options.Validate(); !s.ok()) return s;
  absl::StatusOr<CameraModel> camera = CameraModel::Create(*sensor.intrinsics);
  if (!camera.ok())
    return absl::InvalidArgumentError(
        absl::StrCat(sensor.name, ".intrinsics: ", camera.status().message()));

  CameraCalibrationResult result;
  const Rigid3d T_car_station = T_station_car.Inverse();
  absl::StatusOr<CameraInputs> in =
      CollectCorrespondences(sensor, station, T_car_station, observations);
  if (!in.ok()) return in.status();
  const std::vector<PnpCorrespondence>& points = in->points;
  const std::vector<PnpCorrespondence>& means = in->means;
  result.features_used = static_cast<int>(points.size());
  result.boards_used = static_cast<int>(in->boards_seen.size());
  if (points.empty()) {
    result.reason = "board_not_found";
    result.message = absl::StrCat(sensor.name, ": none of its boards was found in any frame");
    return result;
  }
  if (static_cast<int>(means.size()) < options.min_features) {
    result.reason = "too_few_features";
    result.message =
        absl::StrCat(sensor.name, ": ", means.size(), " distinct features (", result.features_used,
                     " detections), at least ", options.min_features, " needed");
    return result;
  }
  // Frames of a still scene share the detector's systematic error (blur, lens, print): a
  // feature's detections in N frames are not N independent measurements, and a covariance over
  // all of them would shrink as 1/N while the error stays. With the noise estimated from the
  // residuals, the pose is solved on each feature's mean over the frames, whose residuals hold
  // the shared error in full and the independent part divided by N: the sigma then shrinks
  // with frames only as far as the data's own scatter does. A known feature noise
  // (options.pnp.feature_sigma_px, the planner's prediction) is per detection and independent.
  const bool on_means = options.pnp.feature_sigma_px == 0 && means.size() < points.size();
  absl::StatusOr<PnpResult> pnp = SolvePnp(*camera, on_means ? means : points, options.pnp);
  if (!pnp.ok()) return pnp.status();
  result.residual_rms_px = on_means && pnp->outcome == PnpOutcome::kOk
                               ? Rms(ReprojectionErrors(*camera, pnp->T_camera_object, points))
                               : pnp->residual_rms_px;
  if (pnp->outcome != PnpOutcome::kOk) {
    result.reason = PnpOutcomeName(pnp->outcome);
    result.message = absl::StrCat(sensor.name, ": no pose (", result.reason, ")");
    return result;
  }
  const Rigid3d& T_camera_car = pnp->T_camera_object;
  result.solved = true;
  result.mounting = MountingFromSensorPose(T_camera_car, pnp->covariance, sensor);
  result.board_residuals = BoardResiduals(*camera, *in, T_camera_car);
  SetDerived(*camera, sensor, T_camera_car, options, &result);
  SetSeedFormulas(*camera, sensor, station, T_car_station, observations, options, T_camera_car,
                  &result);
  Judge(sensor, *in, T_camera_car, options, &result);
  return result;
}

}  // namespace linecal
