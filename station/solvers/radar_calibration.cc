#include "station/solvers/radar_calibration.h"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <numbers>
#include <span>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"

namespace linecal {
namespace {

// Gauss-Newton in one unknown converges quadratically; the step test is far below any
// meaningful yaw (1e-12 rad) and the iteration cap is a guard, never reached in practice.
constexpr int kMaxIterations = 20;
constexpr double kStepTolerance = 1e-12;  // radians and metres

// Midpoints per axis of the uniform position offset in the 95% interval's mixture: 8 resolve
// a uniform's 95% point to within 1%.
constexpr int kPositionNodes = 8;
// The midpoint of bin i of kPositionNodes equal bins of [−1, 1].
double UniformMidpoint(int i) { return (2.0 * i + 1) / kPositionNodes - 1; }

// The variance of the radar's x and y offset from nominal, uniform within ±tolerance; a zero
// tolerance is kept as 1 µm so that the prior's information stays finite.
Eigen::Vector2d PositionPriorVariance(const SensorModel& sensor) {
  constexpr double kLeastToleranceM = 1e-6;
  const Eigen::Vector2d tol =
      sensor.tolerance.xyz_m.head<2>().cwiseAbs().cwiseMax(kLeastToleranceM);
  return tol.cwiseAbs2() / 3;
}

// M = Rx(roll)ᵀ · Ry(pitch)ᵀ: radar frame from the frame turned by yaw only.
Eigen::Matrix3d PitchRollTransposed(const YawPitchRoll& angles) {
  return RotationFromYawPitchRoll({0, angles.pitch, angles.roll}).transpose();
}

// q = Rz(yaw)ᵀ (p_car − t): the point in the frame turned by yaw only.
Eigen::Vector3d YawFramePoint(double yaw, const Eigen::Vector3d& t, const Eigen::Vector3d& p_car) {
  return Eigen::AngleAxisd(-yaw, Eigen::Vector3d::UnitZ()) * (p_car - t);
}

// Lateral shifts of the position grid over which the joint rounding error is averaged. The
// error of one reflector is a sawtooth of its place in the cell; 16 points resolve the
// weighted sum of a few of them to well under 1% of its RMS.
constexpr int kGridShifts = 16;

// The two-sided 95% point of the standard normal distribution.
constexpr double kZ95 = 1.959963984540054;

// The half-width h of the interval that holds 95% of b + n, b drawn evenly from `offsets` and
// n ~ N(0, σ²): mean over b of P(|b + n| ≤ h) = 0.95, by bisection (the share grows with h).
// A grid error dominated by a few reflectors is close to uniform, whose 95% interval is
// 1.65σ wide, not 1.96σ.
double HalfWidth95(std::span<const double> offsets, double sigma) {
  double widest = 0;
  for (double b : offsets) widest = std::max(widest, std::abs(b));
  const auto share = [&](double h) {
    double p = 0;
    for (double b : offsets) {
      p += 0.5 * (std::erfc((-h - b) / (sigma * std::numbers::sqrt2)) -
                  std::erfc((h - b) / (sigma * std::numbers::sqrt2)));
    }
    return p / static_cast<double>(offsets.size());
  };
  double lo = 0, hi = widest + kZ95 * sigma;  // share(hi) ≥ 0.95
  for (int i = 0; i < 60; ++i) {
    const double mid = 0.5 * (lo + hi);
    (share(mid) < 0.95 ? lo : hi) = mid;
  }
  return hi;
}

// E[round(v + n)] − v for n ~ N(0, r²), v and r in steps: the error left in the mean of many
// readings of v quantised to whole steps, once noise of r steps dithers the rounding. The sum
// runs over the steps within 8r of v (the rest has probability < 1e-15).
double MeanRoundingError(double v, double r) {
  const double f = v - std::round(v);  // the error is periodic in v: take v within ½ step of 0
  if (r < 1e-9) return -f;
  const double reach = std::ceil(8 * r) + 1;
  const double scale = 1 / (r * std::numbers::sqrt2);
  double mean = 0;
  for (double m = -reach; m <= reach; ++m) {
    // P(round(f + n) = m) = Φ((m + ½ − f) / r) − Φ((m − ½ − f) / r), Φ(z) = erfc(−z/√2) / 2.
    mean += m * 0.5 * (std::erfc(-(m + 0.5 - f) * scale) - std::erfc(-(m - 0.5 - f) * scale));
  }
  return mean - f;
}

// ∂azimuth/∂(yaw, dx, dy): the yaw derivative and the x, y part of the position derivative.
Eigen::Vector3d AzimuthJacobian(const YawPitchRoll& angles, const Eigen::Vector3d& t,
                                const Eigen::Vector3d& p_car) {
  const Eigen::Vector3d dt = PredictedAzimuthPositionDerivative(angles, t, p_car);
  return {PredictedAzimuthYawDerivative(angles, t, p_car), dt.x(), dt.y()};
}

// An offset is estimated only where that cuts the yaw's σ by at least a third (its variance to
// 4/9 or less). Estimating an offset direction the azimuths tell but that the yaw is not
// sensitive to buys little and costs much: on the reference station's corner radars (two
// reflectors 0.5 m apart in range) it cut the yaw's σ from 0.30° to 0.29° but doubled its error
// with the radar at its nominal place (p95 0.023° → 0.046°), where real mountings cluster.
constexpr double kEstimatedYawVarianceRatio = 4.0 / 9.0;

using OffsetBasis = Eigen::Matrix<double, 2, Eigen::Dynamic>;  // unit columns, car frame

struct OffsetDirections {
  OffsetBasis observed;                                             // estimated
  Eigen::Matrix2d unobserved_covariance = Eigen::Matrix2d::Zero();  // the prior's, the others
};

// The yaw's variance, linearised, with the offset estimated along the columns of b: each
// reflector's azimuth error (variance 1 / weight) and the true offset (the prior's variance)
// through the fit's gains. `jacobians` are ∂azimuth/∂(yaw, dx, dy).
double LinearYawVariance(std::span<const Eigen::Vector3d> jacobians,
                         std::span<const double> weights, const OffsetBasis& b,
                         const Eigen::Matrix2d& prior) {
  const Eigen::Index m = 1 + b.cols();
  Eigen::MatrixXd information = Eigen::MatrixXd::Zero(m, m);
  information.bottomRightCorner(b.cols(), b.cols()) = b.transpose() * prior * b;
  std::vector<Eigen::VectorXd> reduced;
  for (std::size_t i = 0; i < jacobians.size(); ++i) {
    Eigen::VectorXd j(m);
    j << jacobians[i][0], b.transpose() * jacobians[i].tail<2>();
    information += weights[i] * j * j.transpose();
    reduced.push_back(j);
  }
  const Eigen::RowVectorXd yaw_row = information.inverse().row(0);
  double variance = 0;
  Eigen::Vector2d yaw_per_offset = Eigen::Vector2d::Zero();
  for (std::size_t i = 0; i < jacobians.size(); ++i) {
    const double gain = weights[i] * yaw_row.dot(reduced[i]);
    variance += gain * gain / weights[i];
    yaw_per_offset += gain * jacobians[i].tail<2>();
  }
  return variance + yaw_per_offset.dot(prior.inverse() * yaw_per_offset);
}

// Which directions of the offset to estimate: of the eigen-directions of the offset's
// information once the yaw is solved for (Schur complement), the set (none, either, both)
// that gives the smallest linearised yaw variance, if it passes kEstimatedYawVarianceRatio
// against estimating none.
OffsetDirections ChooseOffsetDirections(std::span<const Eigen::Vector3d> jacobians,
                                        std::span<const double> weights,
                                        const Eigen::Matrix2d& prior) {
  Eigen::Matrix3d information = Eigen::Matrix3d::Zero();
  for (std::size_t i = 0; i < jacobians.size(); ++i) {
    information += weights[i] * jacobians[i] * jacobians[i].transpose();
  }
  const Eigen::Matrix2d offset_information =
      information.bottomRightCorner<2, 2>() -
      information.block<2, 1>(1, 0) * information.block<1, 2>(0, 1) / information(0, 0);
  const Eigen::Matrix2d v =
      Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d>(offset_information).eigenvectors();
  const double none = LinearYawVariance(jacobians, weights, OffsetBasis(2, 0), prior);
  double best = kEstimatedYawVarianceRatio * none;
  int chosen = 0;  // bit k: eigenvector k estimated
  for (int subset = 1; subset < 4; ++subset) {
    OffsetBasis b(2, 0);
    for (int k = 0; k < 2; ++k) {
      if (subset & (1 << k)) {
        b.conservativeResize(Eigen::NoChange, b.cols() + 1);
        b.rightCols<1>() = v.col(k);
      }
    }
    const double variance = LinearYawVariance(jacobians, weights, b, prior);
    if (variance < best) {
      best = variance;
      chosen = subset;
    }
  }
  OffsetDirections out;
  out.observed.resize(2, 0);
  for (int k = 0; k < 2; ++k) {
    if (chosen & (1 << k)) {
      out.observed.conservativeResize(Eigen::NoChange, out.observed.cols() + 1);
      out.observed.rightCols<1>() = v.col(k);
    } else {
      out.unobserved_covariance += v.col(k) * v.col(k).transpose() / v.col(k).dot(prior * v.col(k));
    }
  }
  return out;
}

}  // namespace

absl::Status RadarCalibrationOptions::Validate() const {
  if (min_reflectors < 1) {
    return absl::InvalidArgumentError(
        absl::StrCat("min_reflectors = ", min_reflectors, ": must be >= 1"));
  }
  if (!(max_sigma_fraction_of_tolerance > 0 && std::isfinite(max_sigma_fraction_of_tolerance))) {
    return absl::InvalidArgumentError(
        absl::StrCat("max_sigma_fraction_of_tolerance = ", max_sigma_fraction_of_tolerance,
                     ": must be finite and > 0"));
  }
  return absl::OkStatus();
}

double PredictedAzimuth(const YawPitchRoll& angles, const Eigen::Vector3d& t_car_radar,
                        const Eigen::Vector3d& p_car) {
  const Eigen::Vector3d p =
      PitchRollTransposed(angles) * YawFramePoint(angles.yaw, t_car_radar, p_car);
  return std::atan2(p.y(), p.x());
}

double PredictedAzimuthYawDerivative(const YawPitchRoll& angles, const Eigen::Vector3d& t_car_radar,
                                     const Eigen::Vector3d& p_car) {
  const Eigen::Matrix3d m = PitchRollTransposed(angles);
  const Eigen::Vector3d q = YawFramePoint(angles.yaw, t_car_radar, p_car);
  // d Rz(−yaw)/d yaw · d = −e_z × q = (q_y, −q_x, 0).
  const Eigen::Vector3d p = m * q;
  const Eigen::Vector3d dp = m * Eigen::Vector3d(q.y(), -q.x(), 0);
  // d atan2(y, x) = (x dy − y dx) / (x² + y²).
  return (p.x() * dp.y() - p.y() * dp.x()) / (p.x() * p.x() + p.y() * p.y());
}

Eigen::Vector3d PredictedAzimuthPositionDerivative(const YawPitchRoll& angles,
                                                   const Eigen::Vector3d& t_car_radar,
                                                   const Eigen::Vector3d& p_car) {
  const Eigen::Matrix3d m = PitchRollTransposed(angles);
  const Eigen::Vector3d p = m * YawFramePoint(angles.yaw, t_car_radar, p_car);
  // p = M Rz(−yaw) (p_car − t): ∂p/∂t = −M Rz(−yaw); ∂atan2(y, x)/∂p = (−y, x, 0) / (x² + y²).
  const Eigen::Vector3d d_azimuth_d_p =
      Eigen::Vector3d(-p.y(), p.x(), 0) / p.head<2>().squaredNorm();
  const Eigen::Matrix3d d_p_d_t =
      -m * Eigen::AngleAxisd(-angles.yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  return d_p_d_t.transpose() * d_azimuth_d_p;
}

namespace {

// A found reflector that enters the fit: where it stands and what the radar saw of it.
struct UsedReflector {
  const ExpectedReflector* expected;
  const ReflectorObservation* observed;
};

// The reflectors found with a usable azimuth standard error, in the order of `expected`
// (expected[i] pairs with association.reflectors[i]).
std::vector<UsedReflector> UsableReflectors(std::span<const ExpectedReflector> expected,
                                            const ReflectorAssociation& association) {
  std::vector<UsedReflector> used;
  const size_t n = std::min(expected.size(), association.reflectors.size());
  for (size_t i = 0; i < n; ++i) {
    if (association.reflectors[i].status == ReflectorStatus::kFound &&
        association.reflectors[i].azimuth_se_rad > 0) {
      used.push_back({&expected[i], &association.reflectors[i]});
    }
  }
  return used;
}

// Weights from each reflector's error taken alone. Not from the scatter without the grid's
// part: the grid makes it uneven (a reflector on a cell edge flips between two cells, one in
// the middle never moves), and uneven weights would undo the cancellation of the grid's
// errors between reflectors that a layout can provide. The σ below propagates each part of
// the error through these weights.
double Weight(const UsedReflector& u) {
  return 1 / (u.observed->azimuth_se_rad * u.observed->azimuth_se_rad);
}

// The Gauss-Newton state: the mounting being solved (yaw, and the position's x and y; pitch
// and roll stay nominal) and what it is solved from.
struct YawFit {
  std::span<const UsedReflector> used;
  Eigen::Matrix2d prior;  // the offset's information, car x and y
  YawPitchRoll angles;
  Eigen::Vector3d t;  // t_car_radar
};

// ∂azimuth/∂(yaw, α) of reflector u at the fit's current mounting, α the offset along the
// columns of b.
Eigen::VectorXd ReducedJacobian(const YawFit& fit, const OffsetBasis& b, const UsedReflector& u) {
  const Eigen::Vector3d j = AzimuthJacobian(fit.angles, fit.t, u.expected->p_car);
  Eigen::VectorXd out(1 + b.cols());
  out << j[0], b.transpose() * j.tail<2>();
  return out;
}

// Unknowns θ = (yaw, α): the yaw and the radar's horizontal offset from its nominal position
// along the columns of b (car frame), with the prior that the offset is within ±tolerance
// (variance tolerance² / 3 per axis, the uniform distribution's). Gauss-Newton on the azimuth
// residuals plus the prior, from fit's mounting, which it moves to the solution. Gives
// H = JᵀWJ + P, the information of the last step.
Eigen::MatrixXd FitYawAndOffset(const OffsetBasis& b, YawFit* fit) {
  const Eigen::Index m = 1 + b.cols();
  Eigen::MatrixXd prior_b = Eigen::MatrixXd::Zero(m, m);
  prior_b.bottomRightCorner(b.cols(), b.cols()) = b.transpose() * fit->prior * b;
  Eigen::MatrixXd information = prior_b;
  Eigen::VectorXd theta = Eigen::VectorXd::Zero(m);  // yaw unused: the prior has no yaw part
  for (int it = 0; it < kMaxIterations; ++it) {
    information = prior_b;
    Eigen::VectorXd gradient = -prior_b * theta;
    for (const UsedReflector& u : fit->used) {
      const double w = Weight(u);
      const double r = std::remainder(
          u.observed->azimuth_rad - PredictedAzimuth(fit->angles, fit->t, u.expected->p_car),
          2 * std::numbers::pi);
      const Eigen::VectorXd j = ReducedJacobian(*fit, b, u);
      information += w * j * j.transpose();
      gradient += w * j * r;
    }
    const Eigen::VectorXd step = information.ldlt().solve(gradient);
    theta += step;
    fit->angles.yaw += step[0];
    fit->t.head<2>() += b * step.tail(b.cols());
    if (step.cwiseAbs().maxCoeff() < kStepTolerance) break;
  }
  return information;
}

// The solved fit: which offset directions it estimated, the covariance of (yaw, α) and how
// much the yaw moves per radian of each reflector's azimuth error.
struct YawSolution {
  OffsetDirections directions;
  Eigen::MatrixXd covariance;
  std::vector<double> gain;  // per used reflector
};

// The yaw alone first; at its solution, the offset directions that the reflectors tell, and
// the fit along them. Moves fit's mounting to the solution.
YawSolution SolveYawAndOffset(YawFit* fit) {
  FitYawAndOffset(OffsetBasis(2, 0), fit);
  std::vector<Eigen::Vector3d> jacobians;
  std::vector<double> weights;
  for (const UsedReflector& u : fit->used) {
    jacobians.push_back(AzimuthJacobian(fit->angles, fit->t, u.expected->p_car));
    weights.push_back(Weight(u));
  }
  YawSolution s;
  s.directions = ChooseOffsetDirections(jacobians, weights, fit->prior);
  s.covariance = FitYawAndOffset(s.directions.observed, fit).inverse();
  // The yaw row of H⁻¹ Jᵀ W, the Gauss-Newton step's gain.
  for (const UsedReflector& u : fit->used) {
    s.gain.push_back(Weight(u) *
                     s.covariance.row(0).dot(ReducedJacobian(*fit, s.directions.observed, u)));
  }
  return s;
}

// Σ gain² se², se without the position grid's part; equals 1 / √information when the grid
// has none and the position is known.
double MeasurementSigma(std::span<const UsedReflector> used, std::span<const double> gain) {
  double measurement_variance = 0;
  for (std::size_t i = 0; i < used.size(); ++i) {
    const double se = used[i].observed->azimuth_se_without_position_steps_rad;
    measurement_variance += gain[i] * gain[i] * se * se;
  }
  return std::sqrt(measurement_variance);
}

// The yaw shift that pitch and roll off nominal by (dp, dr) cause: one Gauss-Newton step
// from the solution towards azimuths predicted with them (the shift is far below a degree,
// where one step is exact to well below the noise). Its root mean square over dp, dr uniform
// in ±tolerance uses the 3-point Gauss-Legendre rule per axis (exact for the quartic terms).
double PitchRollSigma(const SensorModel& sensor, const YawFit& fit, std::span<const double> gain) {
  constexpr double kNodes[3] = {-0.7745966692414834, 0.0, 0.7745966692414834};  // ±√(3/5)
  constexpr double kWeights[3] = {5.0 / 18, 8.0 / 18, 5.0 / 18};  // Legendre weights / 2
  double mean_square_shift = 0;
  for (int a = 0; a < 3; ++a) {
    for (int b = 0; b < 3; ++b) {
      YawPitchRoll tilted = fit.angles;
      tilted.pitch += kNodes[a] * sensor.tolerance.pitch_rad;
      tilted.roll += kNodes[b] * sensor.tolerance.roll_rad;
      double yaw_shift = 0;
      for (std::size_t i = 0; i < fit.used.size(); ++i) {
        const Eigen::Vector3d& p_car = fit.used[i].expected->p_car;
        yaw_shift += gain[i] * std::remainder(PredictedAzimuth(tilted, fit.t, p_car) -
                                                  PredictedAzimuth(fit.angles, fit.t, p_car),
                                              2 * std::numbers::pi);
      }
      mean_square_shift += kWeights[a] * kWeights[b] * yaw_shift * yaw_shift;
    }
  }
  return std::sqrt(mean_square_shift);
}

// A reflector's hold on the yaw through the position grid.
struct GridLever {
  Eigen::Vector2d p;          // radar frame, metres
  Eigen::Vector2d noise;      // per-detection σ along x and y, in steps
  Eigen::Vector2d d_azimuth;  // ∂azimuth/∂(x, y) times the reflector's gain
};

// The levers of the used reflectors at the fit's solution, the grid `step` > 0 metres.
std::vector<GridLever> GridLevers(const ReflectorAssociation& association, double step,
                                  const YawFit& fit, std::span<const double> gain) {
  std::vector<GridLever> levers;
  const Eigen::Matrix3d m = PitchRollTransposed(fit.angles);
  for (std::size_t i = 0; i < fit.used.size(); ++i) {
    const Eigen::Vector3d p = m * YawFramePoint(fit.angles.yaw, fit.t, fit.used[i].expected->p_car);
    const double r2 = p.head<2>().squaredNorm();
    const double c = p.x() / std::sqrt(r2), s = p.y() / std::sqrt(r2);
    // Polar noise in Cartesian axes: range noise along the line of sight, azimuth noise
    // across it.
    const double along = association.noise.range_sigma_m;
    const double across = association.noise.azimuth_sigma_rad * std::sqrt(r2);
    levers.push_back(
        {p.head<2>(),
         Eigen::Vector2d(std::hypot(along * c, across * s), std::hypot(along * s, across * c)) /
             step,
         gain[i] * Eigen::Vector2d(-p.y(), p.x()) / r2});
  }
  return levers;
}

// The yaw errors the position grid causes, and their root mean square.
struct GridErrors {
  std::vector<double> errors;  // x node major, kGridShifts per x node
  double rms = 0;
};

// The position grid (ARS408 clusters: 0.2 m in x and y). The noise hardly dithers it across
// the line of sight (0.1° is 0.017 m at 10 m), so each reflector's mean azimuth keeps an
// error fixed by where the reflector sits in its cell, and averaging cycles does not remove
// it. These errors are not independent between reflectors: where they sit relative to each
// other is known (surveyed layout, estimated yaw), and a row laid out at different places in
// the cell cancels them, a row at one place adds them up. Across the line of sight, where
// the whole set sits in the grid is not known beforehand: the yaw being measured moves it
// (0.17 m per degree at 10 m, a cell within the tolerance). Along it, the reflectors ahead
// stay where the layout and the mounting put them, which the calibration takes as nominal.
// So the yaw error the reflectors cause together (one Gauss-Newton step as above) is
// averaged in square over lateral shifts of the set across a whole cell, at the x the
// estimate gives. (Averaging over x too overstated the σ by 10% on the reference station,
// whose row stands at one x: 97% coverage over 3 x 1000 cars.)
// The yaw error at each x offset node (kPositionNodes, over ±x_spread: where the row sits
// along the line of sight is known only that well) and lateral shift of the grid
// (kGridShifts). Needs the grid `step` > 0 metres.
GridErrors PositionGridErrors(const ReflectorAssociation& association, double step, double x_spread,
                              const YawFit& fit, std::span<const double> gain) {
  GridErrors out;
  const std::vector<GridLever> levers = GridLevers(association, step, fit, gain);
  // The radar moved along the car's x moves the reflectors the other way in its frame.
  const Eigen::Matrix3d m = PitchRollTransposed(fit.angles);
  const Eigen::Vector2d x_direction =
      -(m * Eigen::AngleAxisd(-fit.angles.yaw, Eigen::Vector3d::UnitZ()) * Eigen::Vector3d::UnitX())
           .head<2>();
  double mean_square = 0;
  for (int a = 0; a < kPositionNodes; ++a) {
    const Eigen::Vector2d moved = UniformMidpoint(a) * x_spread * x_direction;
    for (int i = 0; i < kGridShifts; ++i) {
      const double shift = (i + 0.5) / kGridShifts;
      double yaw_error = 0;
      for (const GridLever& l : levers) {
        const Eigen::Vector2d p = l.p + moved;
        const double vx = (p.x() - association.resolution.position_x_origin_m) / step;
        const double vy = p.y() / step + shift;
        yaw_error += step * (l.d_azimuth.x() * MeanRoundingError(vx, l.noise.x()) +
                             l.d_azimuth.y() * MeanRoundingError(vy, l.noise.y()));
      }
      out.errors.push_back(yaw_error);
      mean_square += yaw_error * yaw_error;
    }
  }
  out.rms = std::sqrt(mean_square / static_cast<double>(out.errors.size()));
  return out;
}

// How far the yaw moves per metre of a true offset along car x and y: a true offset δ moves
// reflector i's azimuth by ∂azimuth/∂t · δ, which reaches the yaw through its gain (the part
// along unestimated directions whole, the rest as far as the prior's pull towards nominal
// keeps it).
Eigen::Vector2d YawPerOffset(const YawFit& fit, std::span<const double> gain) {
  Eigen::Vector2d yaw_per_offset = Eigen::Vector2d::Zero();
  for (std::size_t i = 0; i < fit.used.size(); ++i) {
    const Eigen::Vector3d j = AzimuthJacobian(fit.angles, fit.t, fit.used[i].expected->p_car);
    yaw_per_offset += gain[i] * j.tail<2>();
  }
  return yaw_per_offset;
}

// The grid error plus the offset's error, for every grid error and offset δ uniform within
// ±tolerance per axis, taken over kPositionNodes midpoints per axis (grid_errors: x node
// major, as PositionGridErrors gives them).
std::vector<double> GridAndOffsetErrors(std::span<const double> grid_errors,
                                        const Eigen::Vector2d& yaw_per_offset,
                                        const Eigen::Vector2d& offset_variance) {
  const std::size_t grid_per_x = grid_errors.size() / kPositionNodes;
  const Eigen::Vector2d offset_bound = (3 * offset_variance).cwiseSqrt();
  std::vector<double> offset_errors;
  for (int i = 0; i < kPositionNodes; ++i) {
    for (int j = 0; j < kPositionNodes; ++j) {
      const Eigen::Vector2d node(UniformMidpoint(i), UniformMidpoint(j));
      const double offset_error = yaw_per_offset.dot(node.cwiseProduct(offset_bound));
      for (std::size_t g = 0; g < grid_per_x; ++g) {
        offset_errors.push_back(grid_errors[i * grid_per_x + g] + offset_error);
      }
    }
  }
  return offset_errors;
}

// Each used reflector's azimuth residual at the solution, and their χ².
void AddResiduals(const YawFit& fit, RadarCalibrationResult* out) {
  for (const UsedReflector& u : fit.used) {
    RadarReflectorResidual res;
    res.reflector_id = u.observed->reflector_id;
    res.azimuth_measured_rad = u.observed->azimuth_rad;
    res.azimuth_predicted_rad = PredictedAzimuth(fit.angles, fit.t, u.expected->p_car);
    res.azimuth_se_rad = u.observed->azimuth_se_rad;
    res.residual_rad =
        std::remainder(res.azimuth_measured_rad - res.azimuth_predicted_rad, 2 * std::numbers::pi);
    out->chi2 += (res.residual_rad / res.azimuth_se_rad) * (res.residual_rad / res.azimuth_se_rad);
    out->residuals.push_back(res);
  }
}

// The verdict from the yaw's σ and its deviation from nominal, with the guard band of
// every verdict (mounting.h, DecideTolerance).
void SetVerdict(const SensorModel& sensor, const RadarCalibrationOptions& options,
                RadarCalibrationResult* out) {
  if (out->yaw_sigma_rad > options.max_sigma_fraction_of_tolerance * sensor.tolerance.yaw_rad) {
    out->verdict = Verdict::kError;
    out->reason = "uncertainty_too_high";
    return;
  }
  switch (DecideTolerance(out->yaw_deviation_rad, out->yaw_sigma_rad, sensor.tolerance.yaw_rad)) {
    case ToleranceDecision::kOutside:
      out->verdict = Verdict::kFail;
      out->reason = "yaw_out_of_tolerance";
      break;
    case ToleranceDecision::kUndecided:
      out->verdict = Verdict::kError;
      out->reason = "near_tolerance_edge";
      break;
    case ToleranceDecision::kInside:
      out->verdict = Verdict::kPass;
      out->reason = "";
      break;
  }
}

}  // namespace

RadarCalibrationResult CalibrateRadarYaw(const SensorModel& sensor,
                                         std::span<const ExpectedReflector> expected,
                                         const ReflectorAssociation& association,
                                         const RadarCalibrationOptions& options) {
  RadarCalibrationResult out;
  const Eigen::Matrix3d r_base = SensorBaseRotation(SensorKind::kRadar);
  const YawPitchRoll nominal = MountingAngles(sensor.T_car_sensor_nominal.RotationMatrix(), r_base);
  const Eigen::Vector3d t_nominal = sensor.T_car_sensor_nominal.translation();
  out.nominal_yaw_rad = nominal.yaw;
  out.pitch_rad = nominal.pitch;
  out.roll_rad = nominal.roll;
  out.yaw_tolerance_rad = sensor.tolerance.yaw_rad;
  out.yaw_rad = nominal.yaw;
  out.T_car_radar = sensor.T_car_sensor_nominal;

  const std::vector<UsedReflector> used = UsableReflectors(expected, association);
  out.reflectors_used = static_cast<int>(used.size());
  if (out.reflectors_used < options.min_reflectors || used.empty()) {
    out.verdict = Verdict::kError;
    out.reason = "too_few_reflectors";
    return out;
  }

  const Eigen::Vector2d offset_variance = PositionPriorVariance(sensor);
  YawFit fit{used, offset_variance.cwiseInverse().asDiagonal(), nominal, t_nominal};
  const YawSolution solution = SolveYawAndOffset(&fit);
  const OffsetBasis& observed = solution.directions.observed;
  out.yaw_rad = fit.angles.yaw;
  out.position_offset_m = (fit.t - t_nominal).head<2>();
  const Eigen::Matrix2d offset_covariance =
      observed * solution.covariance.bottomRightCorner(observed.cols(), observed.cols()) *
          observed.transpose() +
      solution.directions.unobserved_covariance;
  out.position_offset_sigma_m = offset_covariance.diagonal().cwiseSqrt();
  out.yaw_sigma_measurement_rad = MeasurementSigma(used, solution.gain);
  out.yaw_sigma_pitch_roll_rad = PitchRollSigma(sensor, fit, solution.gain);

  const double step = association.resolution.position_step_m;
  // Where the row sits along the line of sight is known to ±the offset's remaining spread
  // along x; one 0 per x node without a grid.
  const double x_spread = std::sqrt(3.0) * out.position_offset_sigma_m.x();
  std::vector<double> grid_errors(kPositionNodes, 0.0);
  if (step > 0) {
    GridErrors grid = PositionGridErrors(association, step, x_spread, fit, solution.gain);
    grid_errors = std::move(grid.errors);
    out.yaw_sigma_position_steps_rad = grid.rms;
  }
  // The offset's part, δ uniform within ±tolerance per axis. The interval takes it over
  // midpoints per axis: one axis alone is uniform, whose 95% interval is 1.65σ wide, not
  // 1.96σ.
  const Eigen::Vector2d yaw_per_offset = YawPerOffset(fit, solution.gain);
  out.yaw_sigma_position_rad = std::sqrt(yaw_per_offset.cwiseAbs2().dot(offset_variance));
  const std::vector<double> offset_errors =
      GridAndOffsetErrors(grid_errors, yaw_per_offset, offset_variance);
  const double gaussian_sigma =
      std::hypot(out.yaw_sigma_measurement_rad, out.yaw_sigma_pitch_roll_rad);
  out.yaw_sigma_rad =
      std::sqrt(gaussian_sigma * gaussian_sigma +
                out.yaw_sigma_position_steps_rad * out.yaw_sigma_position_steps_rad +
                out.yaw_sigma_position_rad * out.yaw_sigma_position_rad);
  out.yaw_ci95_rad = HalfWidth95(offset_errors, gaussian_sigma);
  out.yaw_deviation_rad = std::remainder(fit.angles.yaw - nominal.yaw, 2 * std::numbers::pi);
  out.T_car_radar = Rigid3d(MountingRotation(fit.angles, r_base), fit.t);
  out.dof = out.reflectors_used - 1;  // the prior, not the azimuths, pins the offset
  AddResiduals(fit, &out);
  SetVerdict(sensor, options, &out);
  return out;
}

std::vector<RadarCycle> CalibrationCycles(std::span<const RadarCycle> all,
                                          const SensorModel& sensor) {
  std::vector<RadarCycle> out;
  const bool esr = sensor.model == "esr";
  for (const RadarCycle& c : all) {
    const bool wanted =
        esr ? c.kind == RadarDetectionKind::kTrack
            : c.kind == RadarDetectionKind::kCluster && c.sensor_id == sensor.radar_sensor_id;
    if (wanted) out.push_back(c);
  }
  return out;
}

absl::StatusOr<RadarCalibrationRun> CalibrateRadar(const SensorModel& sensor,
                                                   const StationLayout& layout,
                                                   const Rigid3d& T_station_car,
                                                   std::span<const RadarCycle> cycles,
                                                   const RadarCalibrationOptions& options) {
  if (absl::Status s = options.Validate(); !s.ok()) return s;
  absl::StatusOr<std::vector<ExpectedReflector>> expected =
      ExpectedReflectors(sensor, layout, T_station_car);
  if (!expected.ok()) return expected.status();
  absl::StatusOr<ReflectorAssociationOptions> association_options =
      ReflectorAssociationOptions::ForSensor(sensor);
  if (!association_options.ok()) return association_options.status();
  if (absl::Status s = association_options->Validate(); !s.ok()) {
    return absl::InvalidArgumentError(absl::StrCat("sensor '", sensor.name, "': ", s.message()));
  }
  RadarCalibrationRun run;
  run.expected = *std::move(expected);
  const std::vector<RadarCycle> used = CalibrationCycles(cycles, sensor);
  run.association = AssociateReflectors(used, run.expected, *association_options);
  run.result = CalibrateRadarYaw(sensor, run.expected, run.association, options);
  return run;
}

}  // namespace linecal
