#include "station/solvers/lidar_calibration.h"

#include <ceres/ceres.h>
#include <ceres/rotation.h>

#include <Eigen/Cholesky>
#include <Eigen/Geometry>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"

namespace linecal {
namespace {

// Relative spread below which the hole centres lie on a line (no rotation about it).
constexpr double kCollinearRatio = 1e-3;

// A whitened residual of a LiDAR point (or direction) against its car-frame position:
// (exp(omega) R0 p + t - q) / sigma; directions ignore t.
struct AlignmentCost {
  AlignmentCost(const Eigen::Vector3d& r0_p, const Eigen::Vector3d& q, double sigma, bool direction)
      : r0_p(r0_p), q(q), inv_sigma(1.0 / sigma), direction(direction) {}

  template <typename T>
  bool operator()(const T* omega, const T* t, T* residual) const {
    const T p[3] = {T(r0_p.x()), T(r0_p.y()), T(r0_p.z())};
    T rotated[3];
    ceres::AngleAxisRotatePoint(omega, p, rotated);
    for (int k = 0; k < 3; ++k) {
      const T moved = direction ? rotated[k] : rotated[k] + t[k];
      residual[k] = (moved - T(q[k])) * T(inv_sigma);
    }
    return true;
  }

  Eigen::Vector3d r0_p, q;
  double inv_sigma;
  bool direction;
};

struct Pair {
  Eigen::Vector3d p_lidar, q_car;
  double sigma;
  bool direction;
  bool in_solve = true;  // false: the board's pose residual stands for it
  size_t board = 0;      // index in LidarInputs::boards
};

// A whitened board-pose residual: L^-1 (theta, t) for the board-frame error between the
// measured pose and the one the LiDAR pose predicts, T_meas^-1 * T_lidar_car * T_car_board,
// with small-angle theta = vee(skew part of the rotation) (the errors are far below a
// degree). L: the Cholesky factor of the measured pose's covariance.
struct BoardPoseCost {
  BoardPoseCost(const Eigen::Matrix3d& R0, const Rigid3d& T_lidar_board, const Rigid3d& T_car_board,
                const Eigen::Matrix<double, 6, 6>& L_inv)
      : R0(R0),
        R_meas(T_lidar_board.RotationMatrix()),
        t_meas(T_lidar_board.translation()),
        R_cb(T_car_board.RotationMatrix()),
        t_cb(T_car_board.translation()),
        L_inv(L_inv) {}

  template <typename T>
  bool operator()(const T* omega, const T* t, T* residual) const {
    T dR[9];
    ceres::AngleAxisToRotationMatrix(omega, ceres::ColumnMajorAdapter3x3(dR));
    const Eigen::Map<const Eigen::Matrix<T, 3, 3>> dR_map(dR);
    const Eigen::Matrix<T, 3, 3> R = dR_map * R0.cast<T>();  // R_car_lidar
    const Eigen::Matrix<T, 3, 1> t_cl(t[0], t[1], t[2]);
    // Predicted board pose in the LiDAR frame, then its error in the measured board frame.
    const Eigen::Matrix<T, 3, 3> R_pred = R.transpose() * R_cb.cast<T>();
    const Eigen::Matrix<T, 3, 1> t_pred = R.transpose() * (t_cb.cast<T>() - t_cl);
    const Eigen::Matrix<T, 3, 3> M = R_meas.transpose().cast<T>() * R_pred;
    Eigen::Matrix<T, 6, 1> e;
    e << T(0.5) * (M(2, 1) - M(1, 2)), T(0.5) * (M(0, 2) - M(2, 0)), T(0.5) * (M(1, 0) - M(0, 1)),
        R_meas.transpose().cast<T>() * (t_pred - t_meas.cast<T>());
    const Eigen::Matrix<T, 6, 1> r = L_inv.cast<T>() * e;
    for (int k = 0; k < 6; ++k) residual[k] = r(k);
    return true;
  }

  Eigen::Matrix3d R0, R_meas;
  Eigen::Vector3d t_meas;
  Eigen::Matrix3d R_cb;
  Eigen::Vector3d t_cb;
  Eigen::Matrix<double, 6, 6> L_inv;
};

struct BoardPose {
  Rigid3d T_lidar_board, T_car_board;
  Eigen::Matrix<double, 6, 6> L_inv;
};

// Weighted Kabsch: the rotation and translation minimising Σ w |R p + t - q|² over the
// points (not the directions).
Rigid3d KabschStart(const std::vector<Pair>& pairs) {
  double w_sum = 0;
  Eigen::Vector3d p_mean = Eigen::Vector3d::Zero(), q_mean = Eigen::Vector3d::Zero();
  for (const Pair& x : pairs) {
    if (x.direction) continue;
    const double w = 1.0 / (x.sigma * x.sigma);
    w_sum += w;
    p_mean += w * x.p_lidar;
    q_mean += w * x.q_car;
  }
  p_mean /= w_sum;
  q_mean /= w_sum;
  Eigen::Matrix3d cross = Eigen::Matrix3d::Zero();
  for (const Pair& x : pairs) {
    if (x.direction) continue;
    cross += (x.q_car - q_mean) * (x.p_lidar - p_mean).transpose() / (x.sigma * x.sigma);
  }
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(cross, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d d = Eigen::Matrix3d::Identity();
  d(2, 2) = (svd.matrixU() * svd.matrixV().transpose()).determinant() < 0 ? -1.0 : 1.0;
  const Eigen::Matrix3d R = svd.matrixU() * d * svd.matrixV().transpose();
  return Rigid3d(R, q_mean - R * p_mean);
}

}  // namespace

std::string_view LidarCalibrationOptions::Validate() const {
  if (!(centre_sigma_m > 0 && centre_sigma_m <= 1)) return "centre_sigma_m";
  if (!(normal_sigma_rad > 0 && normal_sigma_rad <= 1)) return "normal_sigma_rad";
  if (!(translation_bound_m >= 0 && translation_bound_m <= 10)) return "translation_bound_m";
  if (!(max_residual_rms_m > 0 && max_residual_rms_m <= 1)) return "max_residual_rms_m";
  if (!(max_sigma_fraction_of_tolerance > 0 && max_sigma_fraction_of_tolerance <= 10)) {
    return "max_sigma_fraction_of_tolerance";
  }
  return {};
}

LidarBoardObservation LidarObservationFromDetection(const std::string& board_id,
                                                    const RoundHoleCloudDetection& detection) {
  constexpr double kMinCentreSigmaM = 0.001;
  LidarBoardObservation o;
  o.board_id = board_id;
  for (const RoundHoleHole& h : detection.holes) o.holes.push_back({h.id, h.p_lidar});
  o.normal_lidar = detection.T_lidar_board.RotationMatrix().col(2);
  // The board enters the solve as its pose with the detector's full covariance: the five
  // centres share the board's in-plane error (with two rings through the holes mostly along
  // the board's y), which no per-centre sigma can express. The centres' sigma only weighs
  // the closed-form start.
  o.T_lidar_board = detection.T_lidar_board;
  o.pose_covariance = detection.pose_covariance;
  o.centre_sigma_m = std::max(kMinCentreSigmaM, detection.in_plane_sigma_m.maxCoeff());
  o.normal_sigma_rad = detection.normal_sigma_rad;
  return o;
}

namespace {

// What the observations give the solve: hole centres and normals against their car-frame
// features, the boards' measured poses, and how many of each enter it.
struct LidarInputs {
  std::vector<Pair> pairs;
  std::vector<std::string> boards;  // the ids of the boards with holes, in observation order
  std::vector<BoardPose> poses;
  int features_used = 0;
  int boards_used = 0;
};

// Adds observation o (of a board of `station`, T_car_station from the aligner) to *in; a
// board without holes adds nothing. InvalidArgument, naming the sensor and the board, for a
// board not in the station, a hole id that is not one of its hole centres, or a pose,
// covariance, position or normal that is not finite or well formed.
absl::Status AddObservation(const SensorModel& sensor, const StationLayout& station,
                            const Rigid3d& T_car_station, const LidarBoardObservation& o,
                            const LidarCalibrationOptions& options, LidarInputs* in) {
  const StationBoard* board = station.FindBoard(o.board_id);
  if (board == nullptr) {
    return absl::InvalidArgumentError(absl::StrCat(sensor.name, ": observed board '", o.board_id,
                                                   "' is not in station '", station.name, "'"));
  }
  if (o.holes.empty()) return absl::OkStatus();
  const size_t board_index = in->boards.size();
  in->boards.push_back(o.board_id);
  const Rigid3d T_car_board = T_car_station * board->T_station_board;
  const double sigma = o.centre_sigma_m > 0 ? o.centre_sigma_m : options.centre_sigma_m;
  const bool by_pose = o.T_lidar_board.has_value();
  if (by_pose) {
    const Eigen::LLT<Eigen::Matrix<double, 6, 6>> llt(o.pose_covariance);
    if (!o.T_lidar_board->Matrix().allFinite() || !o.pose_covariance.allFinite() ||
        !o.pose_covariance.isApprox(o.pose_covariance.transpose()) ||
        llt.info() != Eigen::Success) {
      return absl::InvalidArgumentError(absl::StrCat(
          sensor.name, ": board '", o.board_id,
          "': T_lidar_board must be finite and pose_covariance symmetric positive definite"));
    }
    const Eigen::Matrix<double, 6, 6> L = llt.matrixL();
    in->poses.push_back({*o.T_lidar_board, T_car_board, L.inverse()});
  }
  for (const LidarHoleCentre& h : o.holes) {
    const std::vector<BoardFeature>& features = board->board.features();
    if (h.feature_id < 0 || h.feature_id >= static_cast<int>(features.size()) ||
        features[h.feature_id].kind != FeatureKind::kHoleCentre) {
      return absl::InvalidArgumentError(absl::StrCat(
          sensor.name, ": board '", o.board_id, "' has no hole centre with id ", h.feature_id));
    }
    if (!h.p_lidar.allFinite()) {
      return absl::InvalidArgumentError(absl::StrCat(sensor.name, ": board '", o.board_id,
                                                     "' hole ", h.feature_id,
                                                     ": position is not finite"));
    }
    const Eigen::Vector2d& p = features[h.feature_id].p_board;
    in->pairs.push_back({h.p_lidar, T_car_board * Eigen::Vector3d(p.x(), p.y(), 0), sigma, false,
                         !by_pose, board_index});
    ++in->features_used;
  }
  if (o.normal_lidar) {
    if (!o.normal_lidar->allFinite() || std::abs(o.normal_lidar->norm() - 1) > 1e-6) {
      return absl::InvalidArgumentError(absl::StrCat(
          sensor.name, ": board '", o.board_id, "': normal_lidar must be a finite unit vector"));
    }
    const double nsigma = o.normal_sigma_rad > 0 ? o.normal_sigma_rad : options.normal_sigma_rad;
    in->pairs.push_back({*o.normal_lidar, T_car_board.RotationMatrix().col(2), nsigma, true,
                         !by_pose, board_index});
  }
  ++in->boards_used;
  return absl::OkStatus();
}

// True if the hole centres fix a rigid pose: three or more, not on one line. Needs
// in.features_used > 0.
bool CentresFixAPose(const LidarInputs& in) {
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const Pair& x : in.pairs) mean += x.direction ? Eigen::Vector3d::Zero() : x.q_car;
  mean /= in.features_used;
  Eigen::Matrix3d scatter = Eigen::Matrix3d::Zero();
  for (const Pair& x : in.pairs) {
    if (!x.direction) scatter += (x.q_car - mean) * (x.q_car - mean).transpose();
  }
  const Eigen::Vector3d spread =
      Eigen::JacobiSVD<Eigen::Matrix3d>(scatter).singularValues().cwiseSqrt();
  return in.features_used >= 3 && spread(1) > kCollinearRatio * spread(0);
}

// The solved LiDAR pose in the car frame, and its translation as the solver holds it.
struct LidarSolve {
  bool converged = false;
  Rigid3d T_car_lidar;
  double t[3] = {0, 0, 0};
};

// Ceres from the weighted Kabsch start: the points and normals that stand for themselves and
// the boards' poses, the translation kept within options.translation_bound_m of nominal per
// axis when that is > 0. Dense QR over 6 unknowns, at most 100 iterations.
LidarSolve SolveLidarPose(const SensorModel& sensor, const LidarInputs& in,
                          const LidarCalibrationOptions& options) {
  const Rigid3d start = KabschStart(in.pairs);
  const Eigen::Matrix3d R0 = start.RotationMatrix();
  double omega[3] = {0, 0, 0};
  LidarSolve out;
  double* t = out.t;
  t[0] = start.translation().x();
  t[1] = start.translation().y();
  t[2] = start.translation().z();
  ceres::Problem problem;
  for (const Pair& x : in.pairs) {
    if (!x.in_solve) continue;
    problem.AddResidualBlock(new ceres::AutoDiffCostFunction<AlignmentCost, 3, 3, 3>(
                                 new AlignmentCost(R0 * x.p_lidar, x.q_car, x.sigma, x.direction)),
                             nullptr, omega, t);
  }
  for (const BoardPose& b : in.poses) {
    problem.AddResidualBlock(new ceres::AutoDiffCostFunction<BoardPoseCost, 6, 3, 3>(
                                 new BoardPoseCost(R0, b.T_lidar_board, b.T_car_board, b.L_inv)),
                             nullptr, omega, t);
  }
  const Eigen::Vector3d nominal = sensor.T_car_sensor_nominal.translation();
  if (options.translation_bound_m > 0) {
    for (int k = 0; k < 3; ++k) {
      // Start inside the box, so the bounded solver begins from a feasible point.
      t[k] = std::clamp(t[k], nominal[k] - options.translation_bound_m,
                        nominal[k] + options.translation_bound_m);
      problem.SetParameterLowerBound(t, k, nominal[k] - options.translation_bound_m);
      problem.SetParameterUpperBound(t, k, nominal[k] + options.translation_bound_m);
    }
  }
  ceres::Solver::Options solver;
  solver.linear_solver_type = ceres::DENSE_QR;
  solver.max_num_iterations = 100;
  // Converge to far below the millimetre: 1e-12 relative cost change.
  solver.function_tolerance = 1e-12;
  solver.gradient_tolerance = 1e-14;
  solver.parameter_tolerance = 1e-12;
  solver.logging_type = ceres::SILENT;
  solver.num_threads = 1;
  ceres::Solver::Summary summary;
  ceres::Solve(solver, &problem, &summary);
  out.converged = summary.termination_type == ceres::CONVERGENCE;
  if (!out.converged) return out;
  Eigen::Matrix3d d_rotation;
  ceres::AngleAxisToRotationMatrix(omega, ceres::ColumnMajorAdapter3x3(d_rotation.data()));
  out.T_car_lidar =
      Rigid3d(Eigen::Quaterniond(d_rotation * R0).normalized(), Eigen::Vector3d(t[0], t[1], t[2]));
  return out;
}

// Information JᵀJ of (δθ, δt) in the car frame at the solution: whitened residual Jacobians
// [-[R p]x, I] / σ for points and [-[R n]x, 0] / σ for normals, and the board poses'.
Eigen::Matrix<double, 6, 6> PoseInformation(const LidarSolve& solve, const LidarInputs& in) {
  const Eigen::Matrix3d R = solve.T_car_lidar.RotationMatrix();
  Eigen::Matrix<double, 6, 6> JtJ = Eigen::Matrix<double, 6, 6>::Zero();
  for (const Pair& x : in.pairs) {
    if (!x.in_solve) continue;
    Eigen::Matrix<double, 3, 6> J = Eigen::Matrix<double, 3, 6>::Zero();
    J.leftCols<3>() = -Skew(R * x.p_lidar) / x.sigma;
    if (!x.direction) J.rightCols<3>() = Eigen::Matrix3d::Identity() / x.sigma;
    JtJ += J.transpose() * J;
  }
  // Board poses: their residual's Jacobian at the solution, re-linearised about it (omega = 0
  // there is the same left perturbation of R as the points' -[R p]x).
  for (const BoardPose& b : in.poses) {
    const ceres::AutoDiffCostFunction<BoardPoseCost, 6, 3, 3> cost(
        new BoardPoseCost(R, b.T_lidar_board, b.T_car_board, b.L_inv));
    const double zero[3] = {0, 0, 0};
    const double* parameters[2] = {zero, solve.t};
    double residual[6];
    using RowJacobian = Eigen::Matrix<double, 6, 3, Eigen::RowMajor>;
    // Evaluate fills both; zeroed first, as GCC does not see that through Ceres.
    RowJacobian J_omega = RowJacobian::Zero(), J_t = RowJacobian::Zero();
    double* jacobians[2] = {J_omega.data(), J_t.data()};
    cost.Evaluate(parameters, residual, jacobians);
    Eigen::Matrix<double, 6, 6> J;
    J << J_omega, J_t;
    JtJ += J.transpose() * J;
  }
  return JtJ;
}

// RMS distance of the hole centres, moved by T_car_lidar, from their car-frame features.
double CentreResidualRms(const Rigid3d& T_car_lidar, const LidarInputs& in) {
  double sum_sq = 0;
  for (const Pair& x : in.pairs) {
    if (!x.direction) sum_sq += (T_car_lidar * x.p_lidar - x.q_car).squaredNorm();
  }
  return std::sqrt(sum_sq / in.features_used);
}

// Per board of in.boards, the RMS distance of its hole centres, moved by T_car_lidar, from
// their car-frame features. O(pairs).
std::vector<BoardResidual> BoardCentreResiduals(const Rigid3d& T_car_lidar, const LidarInputs& in) {
  std::vector<BoardResidual> out;
  for (const std::string& id : in.boards) out.push_back({id, 0.0, 0});
  for (const Pair& x : in.pairs) {
    if (x.direction) continue;
    out[x.board].rms += (T_car_lidar * x.p_lidar - x.q_car).squaredNorm();
    ++out[x.board].features;
  }
  for (BoardResidual& b : out) b.rms = std::sqrt(b.rms / std::max(b.features, 1));
  return out;
}

}  // namespace

absl::StatusOr<LidarCalibrationResult> CalibrateLidar(
    const SensorModel& sensor, const StationLayout& station, const Rigid3d& T_station_car,
    std::span<const LidarBoardObservation> observations, const LidarCalibrationOptions& options) {
  if (sensor.kind != SensorKind::kLidar) {
    return absl::InvalidArgumentError(absl::StrCat("sensor ", sensor.name, " is not a LiDAR"));
  }
  if (const std::string_view bad = options.Validate(); !bad.empty()) {
    return absl::InvalidArgumentError(
        absl::StrCat("LidarCalibrationOptions.", std::string(bad), " is out of range"));
  }
  const Rigid3d T_car_station = T_station_car.Inverse();
  LidarCalibrationResult result;
  LidarInputs in;
  for (const LidarBoardObservation& o : observations) {
    if (absl::Status s = AddObservation(sensor, station, T_car_station, o, options, &in); !s.ok())
      return s;
  }
  result.features_used = in.features_used;
  result.boards_used = in.boards_used;
  if (result.features_used == 0) {
    result.reason = "board_not_found";
    result.message = absl::StrCat(sensor.name, ": none of its boards was found");
    return result;
  }
  if (!CentresFixAPose(in)) {
    result.reason = "too_few_features";
    result.message = absl::StrCat(sensor.name, ": ", result.features_used,
                                  " hole centres, not enough off one line to fix a pose");
    return result;
  }

  const LidarSolve solve = SolveLidarPose(sensor, in, options);
  if (!solve.converged) {
    result.reason = "did_not_converge";
    result.message = absl::StrCat(sensor.name, ": the LiDAR solve did not converge");
    return result;
  }
  const Eigen::Vector3d nominal = sensor.T_car_sensor_nominal.translation();
  for (int k = 0; k < 3 && options.translation_bound_m > 0; ++k) {
    // Within a micrometre of the bound counts as on it.
    result.translation_at_bound |=
        std::abs(std::abs(solve.t[k] - nominal[k]) - options.translation_bound_m) < 1e-6;
  }
  result.residual_rms_m = CentreResidualRms(solve.T_car_lidar, in);
  result.board_residuals = BoardCentreResiduals(solve.T_car_lidar, in);
  result.solved = true;
  result.mounting =
      MountingFromCarPose(solve.T_car_lidar, PoseInformation(solve, in).inverse(), sensor);
  if (result.residual_rms_m > options.max_residual_rms_m) {
    result.reason = "residual_too_high";
    result.message = absl::StrFormat(
        "%s: hole centres %.1f mm RMS off the layout (limit %.1f mm): moved board or wrong match",
        sensor.name, result.residual_rms_m * 1e3, options.max_residual_rms_m * 1e3);
    return result;
  }
  const MountingJudgement judgement =
      JudgeMounting(sensor, result.mounting, options.max_sigma_fraction_of_tolerance);
  result.verdict = judgement.verdict;
  result.reason = judgement.reason;
  result.message = judgement.message;
  return result;
}

}  // namespace linecal
