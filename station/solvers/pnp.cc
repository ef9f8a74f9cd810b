#include "station/solvers/pnp.h"

#include <ceres/ceres.h>
#include <ceres/rotation.h>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <Eigen/SVD>
#include <cmath>
#include <limits>
#include <map>
#include <optional>
#include <tuple>
#include <vector>

#include "absl/strings/str_cat.h"
#include "detectors/common/homography.h"

namespace linecal {
namespace {

// Relative singular values below this make the object points collinear (second) or planar
// (third): board coordinates are exact to ~1e-12 m, while the smallest real spread of a set
// of boards is millimetres over metres (1e-3).
constexpr double kDegenerateRatio = 1e-6;
// The virtual camera keeps rays within 85 degrees of its axis: beyond that normalised
// coordinates exceed tan(85°) ≈ 11 and the start loses its conditioning; such a view (a board
// spanning more than 170° of a fisheye) has no closed-form start.
const double kMinVirtualZ = std::cos(85.0 * M_PI / 180.0);

Eigen::Matrix3d NearestRotation(const Eigen::Matrix3d& m) {
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(m, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d d = Eigen::Matrix3d::Identity();
  d(2, 2) = (svd.matrixU() * svd.matrixV().transpose()).determinant() < 0 ? -1.0 : 1.0;
  return svd.matrixU() * d * svd.matrixV().transpose();
}

// The closed-form start in the virtual camera `v` (normalised coordinates m_v of the rays):
// T_v_object, or nullopt when degenerate.
std::optional<Rigid3d> PlanarStart(std::span<const Eigen::Vector3d> p_object,
                                   std::span<const Eigen::Vector2d> m_v,
                                   const Eigen::Vector3d& centroid, Eigen::Matrix3d basis) {
  // basis: columns e1, e2 in the plane and the normal; a proper rotation (det +1).
  if (basis.determinant() < 0) basis.col(2) = -basis.col(2);
  std::vector<Eigen::Vector2d> a(p_object.size());
  for (size_t i = 0; i < p_object.size(); ++i) {
    const Eigen::Vector3d q = basis.transpose() * (p_object[i] - centroid);
    a[i] = q.head<2>();
  }
  const std::optional<HomographyFit> fit = FitHomography(a, m_v);
  if (!fit) return std::nullopt;
  const Eigen::Matrix3d& H = fit->H;
  // H = λ [r1 r2 t]: the scale from the two rotation columns, the sign that puts the
  // centroid (the plane origin, at t) in front of the camera.
  double lambda = 2.0 / (H.col(0).norm() + H.col(1).norm());
  if (H(2, 2) * lambda < 0) lambda = -lambda;
  Eigen::Matrix3d r;
  r.col(0) = lambda * H.col(0);
  r.col(1) = lambda * H.col(1);
  r.col(2) = r.col(0).cross(r.col(1));
  const Rigid3d T_v_plane(NearestRotation(r), lambda * H.col(2));
  const Rigid3d T_plane_object(Eigen::Matrix3d(basis.transpose()), -(basis.transpose() * centroid));
  return T_v_plane * T_plane_object;
}

std::optional<Rigid3d> GeneralStart(std::span<const Eigen::Vector3d> p_object,
                                    std::span<const Eigen::Vector2d> m_v,
                                    const Eigen::Vector3d& centroid) {
  // Normalised DLT: object points centred and scaled to unit mean distance; the normalised
  // image coordinates are already of order one.
  double scale = 0;
  for (const Eigen::Vector3d& p : p_object) scale += (p - centroid).norm();
  scale /= static_cast<double>(p_object.size());
  Eigen::MatrixXd A(2 * p_object.size(), 12);
  for (size_t i = 0; i < p_object.size(); ++i) {
    const Eigen::Vector4d X((p_object[i] - centroid).x() / scale,
                            (p_object[i] - centroid).y() / scale,
                            (p_object[i] - centroid).z() / scale, 1.0);
    const double u = m_v[i].x(), v = m_v[i].y();
    A.row(2 * i) << X.transpose(), Eigen::RowVector4d::Zero(), -u * X.transpose();
    A.row(2 * i + 1) << Eigen::RowVector4d::Zero(), X.transpose(), -v * X.transpose();
  }
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(A, Eigen::ComputeFullV);
  const Eigen::VectorXd p = svd.matrixV().col(11);
  Eigen::Matrix<double, 3, 4> P;
  P << p.segment<4>(0).transpose(), p.segment<4>(4).transpose(), p.segment<4>(8).transpose();
  // P ~ [R | t] up to a scale; the scale with det > 0 is the one that puts the points in
  // front of the camera (a negative scale flips the determinant of the 3x3 block).
  if (P.leftCols<3>().determinant() < 0) P = -P;
  Eigen::JacobiSVD<Eigen::Matrix3d> m(P.leftCols<3>());
  const double s = m.singularValues().mean();
  if (!(s > 0)) return std::nullopt;
  const Eigen::Matrix3d R = NearestRotation(P.leftCols<3>() / s);
  const Eigen::Vector3d t = P.col(3) / s;
  // In object units: p_v = R (p - c) / scale + t, times scale.
  return Rigid3d(R, scale * t - R * centroid);
}

// Reprojection residual of one point, with the rotation as a rotation vector applied on top
// of the start: p_camera = exp(omega) (R0 p_object) + t.
struct ReprojectionCost {
  ReprojectionCost(const CameraModel* camera, const Eigen::Vector3d& r0_p,
                   const Eigen::Vector2d& uv)
      : camera(camera), r0_p(r0_p), uv(uv) {}

  template <typename T>
  bool operator()(const T* omega, const T* t, T* residual) const {
    const T p[3] = {T(r0_p.x()), T(r0_p.y()), T(r0_p.z())};
    T p_camera[3];
    ceres::AngleAxisRotatePoint(omega, p, p_camera);
    for (int k = 0; k < 3; ++k) p_camera[k] += t[k];
    const CameraParameters& cp = camera->parameters();
    T params[kMaxCameraParameterCount];
    for (int k = 0; k < cp.size(); ++k) params[k] = T(cp[k]);
    T projected[2];
    if (camera->type() == CameraModelType::kPinhole) {
      if (!(p_camera[2] > T(0))) return false;  // behind the camera: reject the step
      ProjectPinhole(params, p_camera, projected);
    } else {
      // The fisheye folds on the negative optical axis; reject steps that reach it.
      if (!(p_camera[2] > T(0)) && p_camera[0] * p_camera[0] + p_camera[1] * p_camera[1] == T(0))
        return false;
      ProjectFisheye(params, p_camera, projected);
    }
    residual[0] = projected[0] - T(uv.x());
    residual[1] = projected[1] - T(uv.y());
    return true;
  }

  const CameraModel* camera;
  Eigen::Vector3d r0_p;
  Eigen::Vector2d uv;
};

}  // namespace

const char* PnpOutcomeName(PnpOutcome outcome) {
  switch (outcome) {
    case PnpOutcome::kOk:
      return "";
    case PnpOutcome::kTooFewPoints:
      return "too_few_features";
    case PnpOutcome::kCollinear:
      return "collinear_features";
    case PnpOutcome::kNoStart:
      return "no_initial_pose";
    case PnpOutcome::kNotConverged:
      return "did_not_converge";
  }
  return "no_initial_pose";
}

std::string_view PnpOptions::Validate() const {
  if (!(huber_px > 0 && huber_px <= 100)) return "huber_px";
  if (!(feature_sigma_px >= 0 && feature_sigma_px <= 100)) return "feature_sigma_px";
  if (max_iterations < 1 || max_iterations > 1000) return "max_iterations";
  return {};
}

bool BoardFacesCamera(const Rigid3d& T_camera_board) {
  // The camera sits at -R^T t in the board frame: on the print's side when its z is positive,
  // i.e. when the board normal R e_z points back along the line of sight t.
  const Eigen::Vector3d normal_camera = T_camera_board.RotationMatrix().col(2);
  return normal_camera.dot(T_camera_board.translation()) < 0;
}

std::vector<double> ReprojectionErrors(const CameraModel& camera, const Rigid3d& T_camera_object,
                                       std::span<const PnpCorrespondence> points) {
  std::vector<double> errors(points.size(), std::numeric_limits<double>::infinity());
  for (size_t i = 0; i < points.size(); ++i) {
    Eigen::Vector2d uv;
    if (camera.Project(T_camera_object * points[i].p_object, &uv))
      errors[i] = (uv - points[i].uv_px).norm();
  }
  return errors;
}

namespace {

// InvalidArgument for options out of range or a point that is not finite.
absl::Status CheckPnpInput(std::span<const PnpCorrespondence> points, const PnpOptions& options) {
  if (const std::string_view bad = options.Validate(); !bad.empty()) {
    return absl::InvalidArgumentError(
        absl::StrCat("PnpOptions.", std::string(bad), " is out of range"));
  }
  for (size_t i = 0; i < points.size(); ++i) {
    if (!points[i].p_object.allFinite())
      return absl::InvalidArgumentError(absl::StrCat("points[", i, "].p_object is not finite"));
    if (!points[i].uv_px.allFinite())
      return absl::InvalidArgumentError(absl::StrCat("points[", i, "].uv_px is not finite"));
  }
  return absl::OkStatus();
}

// The object's shape: its centroid, principal axes (columns, by decreasing spread) and square
// root singular values of its scatter.
struct ObjectShape {
  Eigen::Vector3d centroid;
  Eigen::Matrix3d axes;
  Eigen::Vector3d spread;
};

// The shape of the object points (one or more).
ObjectShape ShapeOf(std::span<const PnpCorrespondence> points) {
  ObjectShape s;
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  for (const PnpCorrespondence& c : points) centroid += c.p_object;
  centroid /= static_cast<double>(points.size());
  Eigen::Matrix3d scatter = Eigen::Matrix3d::Zero();
  for (const PnpCorrespondence& c : points)
    scatter += (c.p_object - centroid) * (c.p_object - centroid).transpose();
  Eigen::JacobiSVD<Eigen::Matrix3d> shape(scatter, Eigen::ComputeFullU);
  s.centroid = centroid;
  s.axes = shape.matrixU();
  s.spread = shape.singularValues().cwiseSqrt();
  return s;
}

// The closed-form start T_camera_object: rays turned into the virtual camera that looks along
// their mean, then the planar or general start on the points whose rays stay within 85
// degrees of it (4 or 6 of them needed); nullopt without one.
std::optional<Rigid3d> StartPose(const CameraModel& camera,
                                 std::span<const PnpCorrespondence> points, bool planar,
                                 const ObjectShape& shape) {
  std::vector<Eigen::Vector3d> rays;
  std::vector<Eigen::Vector3d> p_start;
  rays.reserve(points.size());
  Eigen::Vector3d mean_ray = Eigen::Vector3d::Zero();
  for (const PnpCorrespondence& c : points) {
    Eigen::Vector3d ray;
    if (!camera.Unproject(c.uv_px, &ray)) continue;
    rays.push_back(ray);
    p_start.push_back(c.p_object);
    mean_ray += ray;
  }
  const Eigen::Matrix3d R_v_camera =
      Eigen::Quaterniond::FromTwoVectors(mean_ray, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  std::vector<Eigen::Vector2d> m_v;
  std::vector<Eigen::Vector3d> p_used;
  for (size_t i = 0; i < rays.size(); ++i) {
    const Eigen::Vector3d r = R_v_camera * rays[i];
    if (r.z() < kMinVirtualZ) continue;
    m_v.push_back(r.head<2>() / r.z());
    p_used.push_back(p_start[i]);
  }
  std::optional<Rigid3d> T_v_object;
  if (p_used.size() >= (planar ? 4u : 6u)) {
    T_v_object = planar ? PlanarStart(p_used, m_v, shape.centroid, shape.axes)
                        : GeneralStart(p_used, m_v, shape.centroid);
  }
  if (!T_v_object) return std::nullopt;
  return Rigid3d(Eigen::Matrix3d(R_v_camera.transpose()), Eigen::Vector3d::Zero()) * *T_v_object;
}

// Refinement from T_start: rotation vector on top of the start rotation, and the translation,
// Huber-robust reprojection errors, Ceres dense QR. Sets result->T_camera_object and its
// outcome (kOk or kNotConverged).
void RefinePose(const CameraModel& camera, std::span<const PnpCorrespondence> points,
                const PnpOptions& options, const Rigid3d& T_start, PnpResult* result) {
  const Eigen::Matrix3d R0 = T_start.RotationMatrix();
  double omega[3] = {0, 0, 0};
  double t[3] = {T_start.translation().x(), T_start.translation().y(), T_start.translation().z()};
  ceres::Problem problem;
  ceres::LossFunction* loss = new ceres::HuberLoss(options.huber_px);  // owned by the problem
  for (const PnpCorrespondence& c : points) {
    problem.AddResidualBlock(new ceres::AutoDiffCostFunction<ReprojectionCost, 2, 3, 3>(
                                 new ReprojectionCost(&camera, R0 * c.p_object, c.uv_px)),
                             loss, omega, t);
  }
  ceres::Solver::Options solver;
  solver.linear_solver_type = ceres::DENSE_QR;
  solver.max_num_iterations = options.max_iterations;
  // Converge to well below the noise: 1e-12 relative cost change is ~1e-6 of a pixel.
  solver.function_tolerance = 1e-12;
  solver.gradient_tolerance = 1e-14;
  solver.parameter_tolerance = 1e-12;
  solver.logging_type = ceres::SILENT;
  solver.num_threads = 1;
  ceres::Solver::Summary summary;
  ceres::Solve(solver, &problem, &summary);

  Eigen::Matrix3d d_rotation;
  ceres::AngleAxisToRotationMatrix(omega, ceres::ColumnMajorAdapter3x3(d_rotation.data()));
  result->T_camera_object =
      Rigid3d(NearestRotation(d_rotation * R0), Eigen::Vector3d(t[0], t[1], t[2]));
  result->outcome =
      summary.termination_type == ceres::CONVERGENCE ? PnpOutcome::kOk : PnpOutcome::kNotConverged;
}

using Matrix6d = Eigen::Matrix<double, 6, 6>;
using Vector6d = Eigen::Matrix<double, 6, 1>;

// A noise class's σ² from k explainable degrees of freedom has a relative standard error of
// about sqrt(2/k), its σ about 1/sqrt(2k); the σ bar (error/σ 0.8 to 1.25) allows ±25%, so
// one standard error stays inside it from k = 8. A class below that (the front camera's
// one-board classes, 4.5 to 5.7) may come out far too small, the unsafe side for verdicts: it
// takes the larger of its own σ and every residual's, or, a class of enough marker corners,
// its markers' errors (kMarkerMiddleDof; ClassNoises, docs/solvers.md).
constexpr double kSteadyClassDof = 8.0;

// The markers' middle Σ_m g_m g_mᵀ is a 6 x 6 matrix estimated from one term a marker; each of
// its six directions needs what one σ needs, so a class takes it from 6 kSteadyClassDof marker
// degrees of freedom up (about 25 markers). With 9 tags (d about 17) the pose's σ came out up to
// 26% small, coverage 0.886; with 16, 0.916 (docs/solvers.md, "Marker classes on new cars").
constexpr double kMarkerMiddleDof = 6 * kSteadyClassDof;

// One board's share of the normal equations at the solution: J_bᵀJ_b, J_bᵀr_b, its points.
struct BoardTerms {
  int noise_class = 0;
  Matrix6d JtJ = Matrix6d::Zero();
  Vector6d Jtr = Vector6d::Zero();
  int points = 0;
};

// One marker's corners on a board (PnpCorrespondence::marker): the sums of their Jacobians and
// residuals (the shift they share), and Σ J_iᵀr_i (what moves the pose of the marker's error).
struct MarkerTerms {
  int noise_class = 0;
  Eigen::Matrix<double, 2, 6> J_sum = Eigen::Matrix<double, 2, 6>::Zero();
  Eigen::Vector2d r_sum = Eigen::Vector2d::Zero();
  Vector6d Jtr = Vector6d::Zero();
  int corners = 0;
};

// The per-board and per-marker terms of every point, keyed by (noise class, board) and
// (noise class, board, marker).
struct CovarianceTerms {
  std::map<std::pair<int, int>, BoardTerms> boards;
  std::map<std::tuple<int, int, int>, MarkerTerms> markers;
};

// Board b's terms of σ_c² (pnp.h): g_bᵀ(J_bᵀJ_b)⁺g_b, the part of its residuals a pose change
// of the board explains, and rank(J_bᵀJ_b) − tr(A J_bᵀJ_b), that part's expectation over σ²
// when every feature has noise σ (the pseudo-inverse and rank serve a board too small to fix a
// pose on its own).
std::pair<double, double> ExplainedResidual(const BoardTerms& b, const Matrix6d& JtJ_inverse) {
  const Eigen::SelfAdjointEigenSolver<Matrix6d> eigen(b.JtJ);
  const Vector6d projected = eigen.eigenvectors().transpose() * b.Jtr;
  const double floor = 1e-12 * eigen.eigenvalues().maxCoeff();
  double explained = 0;
  int rank = 0;
  for (int k = 0; k < 6; ++k) {
    if (!(eigen.eigenvalues()[k] > floor)) continue;
    explained += projected[k] * projected[k] / eigen.eigenvalues()[k];
    ++rank;
  }
  return {explained, rank - (JtJ_inverse * b.JtJ).trace()};
}

// A class's markers (pnp.h): Σ_m n_m |r̄_m|², the residuals' part shared by each marker's n_m
// corners; its expectation over σ² under independent noise σ, Σ_m (2 − n_m tr(A J̄_mᵀJ̄_m));
// the markers; and the class's points that are not marker corners.
struct MarkerShift {
  double shift = 0;
  double dof = 0;
  int markers = 0;
  int other_points = 0;
};

// Per noise class (every class has an entry), its MarkerShift.
std::map<int, MarkerShift> MarkerShifts(const CovarianceTerms& terms, const Matrix6d& JtJ_inverse) {
  std::map<int, MarkerShift> out;
  for (const auto& [key, b] : terms.boards) out[b.noise_class].other_points += b.points;
  for (const auto& [key, m] : terms.markers) {
    MarkerShift& s = out[m.noise_class];
    s.other_points -= m.corners;
    s.shift += m.r_sum.squaredNorm() / m.corners;
    s.dof += 2 - (JtJ_inverse * m.J_sum.transpose() * m.J_sum).trace() / m.corners;
    ++s.markers;
  }
  return out;
}

// A noise class's share of the covariance (pnp.h): a feature σ² times its boards' J_bᵀJ_b, or,
// by_markers, its markers' own pose-relevant errors, scale Σ_m g_m g_mᵀ (sigma_sq then the
// markers' shift σ², for PnpResult::sigma_px).
struct ClassNoise {
  double sigma_sq = 0;
  bool by_markers = false;
  double scale = 1;  // 2 × markers / their degrees of freedom: undoes the fit's share
};

// Each noise class's noise (pnp.h): its own σ² from its boards' explained residuals from
// kSteadyClassDof degrees of freedom up; below, its markers' errors when its points are marker
// corners with kMarkerMiddleDof marker degrees of freedom, else the larger of its own σ² and
// every residual's.
std::map<int, ClassNoise> ClassNoises(const CovarianceTerms& terms, const Matrix6d& JtJ_inverse,
                                      double pooled_sigma) {
  std::map<int, std::pair<double, double>> sums;  // per class: Σ explained, Σ degrees of freedom
  for (const auto& [key, b] : terms.boards) {
    const auto [explained, dof] = ExplainedResidual(b, JtJ_inverse);
    sums[b.noise_class].first += explained;
    sums[b.noise_class].second += dof;
  }
  const std::map<int, MarkerShift> shifts = MarkerShifts(terms, JtJ_inverse);
  std::map<int, ClassNoise> out;
  for (const auto& [c, sum] : sums) {
    const double own = sum.second > 0 ? sum.first / sum.second : 0.0;
    const MarkerShift& m = shifts.at(c);
    if (sum.second >= kSteadyClassDof) {
      out[c] = {own};
    } else if (m.other_points == 0 && m.dof >= kMarkerMiddleDof) {
      out[c] = {m.shift / m.dof, true, 2.0 * m.markers / m.dof};
    } else {
      out[c] = {std::max(own, pooled_sigma * pooled_sigma)};
    }
  }
  return out;
}

// The sandwich covariance A (Σ_b σ_c(b)² J_bᵀJ_b + Σ_m s_c(m) g_m g_mᵀ) A of pnp.h; sets
// result->sigma_px to the RMS of the points' σ.
void SetClassCovariance(const CovarianceTerms& terms, const Matrix6d& JtJ_inverse,
                        double pooled_sigma, PnpResult* result) {
  const std::map<int, ClassNoise> noise = ClassNoises(terms, JtJ_inverse, pooled_sigma);
  Matrix6d information = Matrix6d::Zero();
  double sum_sigma_sq = 0;
  int points = 0;
  for (const auto& [key, b] : terms.boards) {
    const ClassNoise& n = noise.at(b.noise_class);
    if (!n.by_markers) information += n.sigma_sq * b.JtJ;
    sum_sigma_sq += n.sigma_sq * b.points;
    points += b.points;
  }
  for (const auto& [key, m] : terms.markers) {
    const ClassNoise& n = noise.at(m.noise_class);
    if (n.by_markers) information += n.scale * m.Jtr * m.Jtr.transpose();
  }
  result->sigma_px = std::sqrt(sum_sigma_sq / points);
  result->covariance = JtJ_inverse * information * JtJ_inverse;
}

// Adds one point's Jacobian J and residual r to its board's and its marker's terms.
void AddPointTerms(const PnpCorrespondence& c, const Eigen::Matrix<double, 2, 6>& J,
                   const Eigen::Vector2d& r, CovarianceTerms* terms) {
  BoardTerms& b = terms->boards[{c.noise_class, c.board}];
  b.noise_class = c.noise_class;
  b.JtJ += J.transpose() * J;
  b.Jtr += J.transpose() * r;
  ++b.points;
  if (c.marker < 0) return;
  MarkerTerms& m = terms->markers[{c.noise_class, c.board, c.marker}];
  m.noise_class = c.noise_class;
  m.J_sum += J;
  m.r_sum += r;
  m.Jtr += J.transpose() * r;
  ++m.corners;
}

// Residuals and the Jacobian of every reprojection at result->T_camera_object, for the
// covariance: d uv / d(δθ, δt) = d uv / d p_camera * [-[R p]x, I]. Sets the residuals, sigma
// and covariance (pnp.h: one σ, or per noise class); kNotConverged (and infinite residuals)
// when the pose puts a point outside the lens or the covariance is not finite.
void SetResidualsAndCovariance(const CameraModel& camera, std::span<const PnpCorrespondence> points,
                               const PnpOptions& options, PnpResult* result) {
  CovarianceTerms terms;
  double sum_sq = 0;
  bool all_projected = true;
  const Eigen::Matrix3d R = result->T_camera_object.RotationMatrix();
  for (const PnpCorrespondence& c : points) {
    const Eigen::Vector3d rp = R * c.p_object;
    Eigen::Vector2d uv;
    ProjectionPointJacobian d_uv_d_p;
    if (!camera.Project(rp + result->T_camera_object.translation(), &uv, &d_uv_d_p)) {
      all_projected = false;  // the pose puts a point outside the lens: no fit
      continue;
    }
    const Eigen::Vector2d r = uv - c.uv_px;
    sum_sq += r.squaredNorm();
    result->max_residual_px = std::max(result->max_residual_px, r.norm());
    Eigen::Matrix<double, 3, 6> d_p;
    d_p << -Skew(rp), Eigen::Matrix3d::Identity();
    AddPointTerms(c, d_uv_d_p * d_p, r, &terms);
  }
  const double n = static_cast<double>(points.size());
  if (!all_projected) {
    result->outcome = PnpOutcome::kNotConverged;
    result->residual_rms_px = result->max_residual_px = std::numeric_limits<double>::infinity();
    return;
  }
  result->residual_rms_px = std::sqrt(sum_sq / n);
  Matrix6d JtJ = Matrix6d::Zero();
  for (const auto& [key, b] : terms.boards) JtJ += b.JtJ;
  const Matrix6d JtJ_inverse = JtJ.inverse();
  if (options.feature_sigma_px > 0 || terms.boards.size() == 1) {
    result->sigma_px =
        options.feature_sigma_px > 0 ? options.feature_sigma_px : std::sqrt(sum_sq / (2 * n - 6));
    result->covariance = result->sigma_px * result->sigma_px * JtJ_inverse;
  } else {
    SetClassCovariance(terms, JtJ_inverse, std::sqrt(sum_sq / (2 * n - 6)), result);
  }
  if (!result->covariance.allFinite()) result->outcome = PnpOutcome::kNotConverged;
}

}  // namespace

absl::StatusOr<PnpResult> SolvePnp(const CameraModel& camera,
                                   std::span<const PnpCorrespondence> points,
                                   const PnpOptions& options) {
  if (absl::Status s = CheckPnpInput(points, options); !s.ok()) return s;
  PnpResult result;
  result.points = static_cast<int>(points.size());
  if (points.size() < 4) {
    result.outcome = PnpOutcome::kTooFewPoints;
    return result;
  }
  // The object's shape: collinear, planar or general.
  const ObjectShape shape = ShapeOf(points);
  if (!(shape.spread(1) > kDegenerateRatio * shape.spread(0))) {
    result.outcome = PnpOutcome::kCollinear;
    return result;
  }
  result.planar = shape.spread(2) <= kDegenerateRatio * shape.spread(0);
  if (!result.planar && points.size() < 6) {
    result.outcome = PnpOutcome::kTooFewPoints;
    return result;
  }
  const std::optional<Rigid3d> T_start = StartPose(camera, points, result.planar, shape);
  if (!T_start) {
    result.outcome = PnpOutcome::kNoStart;
    return result;
  }
  RefinePose(camera, points, options, *T_start, &result);
  SetResidualsAndCovariance(camera, points, options, &result);
  return result;
}

}  // namespace linecal
