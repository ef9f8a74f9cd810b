#include "station/camera/camera_model.h"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <array>
#include <cmath>
#include <complex>
#include <numbers>
#include <optional>

#include "absl/strings/str_cat.h"
#include "absl/strings/string_view.h"
#include "detectors/core/image_view.h"

namespace linecal {
namespace {

constexpr double kEps = std::numeric_limits<double>::epsilon();
constexpr double kInf = std::numeric_limits<double>::infinity();

// Newton on the distortion stops once the residual is below this many ulps of the sum of the
// magnitudes of the terms of the distortion polynomial: Horner's rule for the degree-3
// polynomial in r² plus the tangential terms and the subtraction of the target round off by
// at most about 4 such ulps, and the best representable solution leaves about as much again;
// 16 doubles that so that a converged iteration is always recognised.
constexpr double kResidualUlps = 16.0;
// ... or once the Newton step is below this many ulps of the solution: a quadratically
// converging step that small means the solution is already as exact as doubles allow.
constexpr double kStepUlps = 4.0;
// Newton from the optical axis reaches double precision in 4-8 iterations on real lenses
// (it converges quadratically once within the basin); 50 only bounds the cost of a pixel
// that has no valid ray and makes the damped iteration crawl along the region's edge.
constexpr int kMaxPinholeIterations = 50;
// Step halvings of the damped pinhole Newton step. A step shrunk by 2^-60 (1e-18) no longer
// moves a solution of realistic size (|xy| ~ 0.01..10) by more than rounding.
constexpr int kMaxStepHalvings = 60;
// The safeguarded 1-D Newton on theta halves its bracket at least every second iteration;
// bisection alone shrinks [0, pi] to one ulp of theta in about 54 halvings, so 100
// iterations always suffice.
constexpr int kMaxFisheyeIterations = 100;
// A companion-matrix eigenvalue whose imaginary part is below this fraction of its modulus
// counts as a real root. A double root (a polynomial touching zero) comes out as a complex
// pair split by about sqrt(eps) = 1.5e-8 relative; counting it as real keeps the valid
// region on the safe side.
constexpr double kNearRealRelative = 1e-6;
// Largest polynomial degree passed to SmallestPositiveRoot (the pinhole bound in r).
constexpr int kMaxRootDegree = 6;

absl::Status BadField(absl::string_view name, double value, absl::string_view requirement) {
  return absl::InvalidArgumentError(absl::StrCat(name, " = ", value, ": ", requirement));
}

absl::Status CheckFinite(absl::string_view name, double value) {
  return std::isfinite(value) ? absl::OkStatus() : BadField(name, value, "must be finite");
}

// Smallest positive real root of sum_i c[i] x^i, +inf if there is none, nullopt if the
// eigen decomposition fails. From the eigenvalues of the companion matrix.
template <std::size_t N>
std::optional<double> SmallestPositiveRoot(const std::array<double, N>& c) {
  static_assert(N - 1 <= kMaxRootDegree);
  int degree = static_cast<int>(N) - 1;
  while (degree > 0 && c[degree] == 0.0) --degree;
  if (degree == 0) return kInf;
  using Companion =
      Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxRootDegree, kMaxRootDegree>;
  Companion companion = Companion::Zero(degree, degree);
  for (int i = 0; i < degree; ++i) {
    if (i + 1 < degree) companion(i + 1, i) = 1.0;
    companion(i, degree - 1) = -c[i] / c[degree];
  }
  const Eigen::EigenSolver<Companion> solver(companion, /*computeEigenvectors=*/false);
  if (solver.info() != Eigen::Success) return std::nullopt;
  double smallest = kInf;
  for (int i = 0; i < degree; ++i) {
    const std::complex<double> root = solver.eigenvalues()(i);
    if (root.real() > 0.0 && std::abs(root.imag()) <= kNearRealRelative * std::abs(root)) {
      smallest = std::min(smallest, root.real());
    }
  }
  return smallest;
}

// The pinhole distortion at undistorted normalised coordinates xy (the formula of
// ProjectPinhole), its 2x2 Jacobian, and a bound on the magnitude of its terms (the scale of
// its rounding error).
struct PinholeDistortion {
  Eigen::Vector2d xy_d;
  Eigen::Matrix2d d_xy_d_d_xy;
  double term_magnitude;
};

PinholeDistortion DistortPinhole(const CameraIntrinsics& c, const Eigen::Vector2d& xy) {
  const double x = xy.x();
  const double y = xy.y();
  const double xx = x * x;
  const double yy = y * y;
  const double x_y = x * y;
  const double r2 = xx + yy;
  const double radial = 1.0 + r2 * (c.k1 + r2 * (c.k2 + r2 * c.k3));
  const double d_radial_d_r2 = c.k1 + r2 * (2.0 * c.k2 + 3.0 * c.k3 * r2);
  PinholeDistortion d;
  d.xy_d.x() = x * radial + 2.0 * c.p1 * x_y + c.p2 * (r2 + 2.0 * xx);
  d.xy_d.y() = y * radial + c.p1 * (r2 + 2.0 * yy) + 2.0 * c.p2 * x_y;
  // Radial part: radial * I + 2 radial' xy xy^T. The tangential part is
  // 2 (q.xy) xy + r² q with q = (p2, p1); its Jacobian is 2 xy q^T + 2 (q.xy) I + 2 q xy^T.
  const Eigen::Vector2d q(c.p2, c.p1);
  d.d_xy_d_d_xy = (radial + 2.0 * q.dot(xy)) * Eigen::Matrix2d::Identity() +
                  2.0 * d_radial_d_r2 * xy * xy.transpose() +
                  2.0 * (xy * q.transpose() + q * xy.transpose());
  d.term_magnitude =
      std::sqrt(r2) * (1.0 + r2 * (std::abs(c.k1) + r2 * (std::abs(c.k2) + r2 * std::abs(c.k3)))) +
      3.0 * q.norm() * r2;
  return d;
}

// theta_d(theta) of the fisheye, and its derivative.
double FisheyeThetaD(const CameraIntrinsics& c, double theta) {
  const double t2 = theta * theta;
  return theta * (1.0 + t2 * (c.k1 + t2 * (c.k2 + t2 * (c.k3 + t2 * c.k4))));
}

double FisheyeThetaDDerivative(const CameraIntrinsics& c, double theta) {
  const double t2 = theta * theta;
  return 1.0 + t2 * (3.0 * c.k1 + t2 * (5.0 * c.k2 + t2 * (7.0 * c.k3 + t2 * 9.0 * c.k4)));
}

// Sum of the magnitudes of the terms of theta_d(theta): the scale of its rounding error.
double FisheyeTermMagnitude(const CameraIntrinsics& c, double theta) {
  const double t2 = theta * theta;
  return theta * (1.0 + t2 * (std::abs(c.k1) +
                              t2 * (std::abs(c.k2) + t2 * (std::abs(c.k3) + t2 * std::abs(c.k4)))));
}

}  // namespace

const char* CameraModelTypeName(CameraModelType type) {
  switch (type) {
    case CameraModelType::kPinhole:
      return "pinhole";
    case CameraModelType::kFisheye:
      return "fisheye";
  }
  return "unknown";
}

int CameraParameterCount(CameraModelType type) {
  switch (type) {
    case CameraModelType::kPinhole:
      return kPinholeParameterCount;
    case CameraModelType::kFisheye:
      return kFisheyeParameterCount;
  }
  return 0;
}

const char* CameraParameterName(CameraModelType type, int index) {
  static constexpr std::array<const char*, kPinholeParameterCount> kPinholeNames = {
      "fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3"};
  static constexpr std::array<const char*, kFisheyeParameterCount> kFisheyeNames = {
      "fx", "fy", "cx", "cy", "k1", "k2", "k3", "k4"};
  if (index < 0 || index >= CameraParameterCount(type)) return "";
  return type == CameraModelType::kPinhole ? kPinholeNames[index] : kFisheyeNames[index];
}

CameraParameters ToCameraParameters(const CameraIntrinsics& c) {
  CameraParameters p(CameraParameterCount(c.type));
  if (c.type == CameraModelType::kPinhole) {
    p << c.fx, c.fy, c.cx, c.cy, c.k1, c.k2, c.p1, c.p2, c.k3;
  } else if (c.type == CameraModelType::kFisheye) {
    p << c.fx, c.fy, c.cx, c.cy, c.k1, c.k2, c.k3, c.k4;
  }
  return p;
}

CameraIntrinsics CameraIntrinsicsFromParameters(CameraModelType type, int width, int height,
                                                const double* parameters) {
  CameraIntrinsics c;
  c.type = type;
  c.width = width;
  c.height = height;
  if (CameraParameterCount(type) == 0) return c;
  c.fx = parameters[0];
  c.fy = parameters[1];
  c.cx = parameters[2];
  c.cy = parameters[3];
  c.k1 = parameters[4];
  c.k2 = parameters[5];
  if (type == CameraModelType::kPinhole) {
    c.p1 = parameters[6];
    c.p2 = parameters[7];
    c.k3 = parameters[8];
  } else {
    c.k3 = parameters[6];
    c.k4 = parameters[7];
  }
  return c;
}

absl::Status CameraIntrinsics::Validate() const {
  if (CameraParameterCount(type) == 0) {
    return BadField("type", static_cast<int>(type), "must be pinhole or fisheye");
  }
  const auto check_side = [](absl::string_view name, int side) {
    return side >= 1 && side <= kMaxImageSide
               ? absl::OkStatus()
               : BadField(name, side, absl::StrCat("must be in [1, ", kMaxImageSide, "]"));
  };
  if (absl::Status s = check_side("width", width); !s.ok()) return s;
  if (absl::Status s = check_side("height", height); !s.ok()) return s;
  const auto check_focal = [](absl::string_view name, double f) {
    return std::isfinite(f) && f > 0.0 ? absl::OkStatus()
                                       : BadField(name, f, "must be finite and > 0");
  };
  if (absl::Status s = check_focal("fx", fx); !s.ok()) return s;
  if (absl::Status s = check_focal("fy", fy); !s.ok()) return s;
  // A principal point off the image area means a failed calibration on the cameras this
  // station sees (no shift lenses), so it is refused rather than carried into a solve.
  const auto check_centre = [](absl::string_view name, double centre, int side) {
    return std::isfinite(centre) && centre >= -0.5 && centre <= side - 0.5
               ? absl::OkStatus()
               : BadField(
                     name, centre,
                     absl::StrCat("must be finite and in the image, [-0.5, ", side - 0.5, "]"));
  };
  if (absl::Status s = check_centre("cx", cx, width); !s.ok()) return s;
  if (absl::Status s = check_centre("cy", cy, height); !s.ok()) return s;
  for (const auto& [name, value] : {std::pair<absl::string_view, double>{"k1", k1},
                                    {"k2", k2},
                                    {"k3", k3},
                                    {"k4", k4},
                                    {"p1", p1},
                                    {"p2", p2}}) {
    if (absl::Status s = CheckFinite(name, value); !s.ok()) return s;
  }
  if (type == CameraModelType::kPinhole && k4 != 0.0) {
    return BadField("k4", k4, "must be 0 for a pinhole camera (OpenCV's model has k1..k3)");
  }
  if (type == CameraModelType::kFisheye) {
    if (p1 != 0.0) return BadField("p1", p1, "must be 0 for a fisheye camera");
    if (p2 != 0.0) return BadField("p2", p2, "must be 0 for a fisheye camera");
  }
  return absl::OkStatus();
}

CameraModel::CameraModel(const CameraIntrinsics& intrinsics)
    : intrinsics_(intrinsics), parameters_(ToCameraParameters(intrinsics)) {}

absl::StatusOr<CameraModel> CameraModel::Create(const CameraIntrinsics& intrinsics) {
  if (absl::Status s = intrinsics.Validate(); !s.ok()) return s;
  CameraModel model(intrinsics);
  const CameraIntrinsics& c = intrinsics;
  if (c.type == CameraModelType::kPinhole) {
    // The lower bound on the eigenvalues of the symmetric part of the distortion Jacobian
    // (header): min over the radial eigenvalues, each minus the tangential bound 6 |q| r.
    const double tangential = 6.0 * std::hypot(c.p1, c.p2);
    const std::optional<double> tangent_direction =
        SmallestPositiveRoot(std::array<double, 7>{1.0, -tangential, c.k1, 0.0, c.k2, 0.0, c.k3});
    const std::optional<double> radial_direction = SmallestPositiveRoot(
        std::array<double, 7>{1.0, -tangential, 3.0 * c.k1, 0.0, 5.0 * c.k2, 0.0, 7.0 * c.k3});
    if (!tangent_direction || !radial_direction) {
      return absl::InvalidArgumentError(
          "k1, k2, k3, p1, p2: cannot find where the distortion folds");
    }
    model.max_radius_ = std::min(*tangent_direction, *radial_direction);
    model.max_angle_rad_ = std::atan(model.max_radius_);
  } else {
    // d theta_d / d theta as a polynomial in theta².
    const std::optional<double> theta2 = SmallestPositiveRoot(
        std::array<double, 5>{1.0, 3.0 * c.k1, 5.0 * c.k2, 7.0 * c.k3, 9.0 * c.k4});
    if (!theta2) {
      return absl::InvalidArgumentError("k1, k2, k3, k4: cannot find where the distortion folds");
    }
    model.max_angle_rad_ = std::min(std::sqrt(*theta2), std::numbers::pi);
    model.max_theta_d_ = FisheyeThetaD(c, model.max_angle_rad_);
  }
  return model;
}

bool CameraModel::IsInImage(const Eigen::Vector2d& uv_px) const {
  return uv_px.x() >= -0.5 && uv_px.x() <= intrinsics_.width - 0.5 && uv_px.y() >= -0.5 &&
         uv_px.y() <= intrinsics_.height - 0.5;
}

bool CameraModel::Project(const Eigen::Vector3d& p_camera, Eigen::Vector2d* uv_px,
                          ProjectionPointJacobian* d_uv_d_p,
                          ProjectionParameterJacobian* d_uv_d_parameters) const {
  if (!p_camera.allFinite()) return false;
  return intrinsics_.type == CameraModelType::kPinhole
             ? ProjectPinholeAnalytic(p_camera, uv_px, d_uv_d_p, d_uv_d_parameters)
             : ProjectFisheyeAnalytic(p_camera, uv_px, d_uv_d_p, d_uv_d_parameters);
}

bool CameraModel::ProjectPinholeAnalytic(const Eigen::Vector3d& p_camera, Eigen::Vector2d* uv_px,
                                         ProjectionPointJacobian* d_uv_d_p,
                                         ProjectionParameterJacobian* d_uv_d_parameters) const {
  const CameraIntrinsics& c = intrinsics_;
  const double z = p_camera.z();
  if (!(z > 0.0)) return false;
  const Eigen::Vector2d xy(p_camera.x() / z, p_camera.y() / z);
  const double r2 = xy.squaredNorm();
  if (!(r2 < max_radius_ * max_radius_)) return false;
  const PinholeDistortion d = DistortPinhole(c, xy);
  const Eigen::Vector2d uv(c.fx * d.xy_d.x() + c.cx, c.fy * d.xy_d.y() + c.cy);
  if (!uv.allFinite()) return false;
  *uv_px = uv;
  if (d_uv_d_p != nullptr) {
    // d xy / d p = [I / z, -xy / z].
    Eigen::Matrix<double, 2, 3> d_xy_d_p;
    d_xy_d_p << 1.0 / z, 0.0, -xy.x() / z,  //
        0.0, 1.0 / z, -xy.y() / z;
    *d_uv_d_p = Eigen::Vector2d(c.fx, c.fy).asDiagonal() * d.d_xy_d_d_xy * d_xy_d_p;
  }
  if (d_uv_d_parameters != nullptr) {
    const double x = xy.x();
    const double y = xy.y();
    const double r4 = r2 * r2;
    ProjectionParameterJacobian& j = *d_uv_d_parameters;
    j.setZero(2, kPinholeParameterCount);
    j(0, 0) = d.xy_d.x();
    j(1, 1) = d.xy_d.y();
    j(0, 2) = 1.0;
    j(1, 3) = 1.0;
    j(0, 4) = c.fx * x * r2;
    j(1, 4) = c.fy * y * r2;
    j(0, 5) = c.fx * x * r4;
    j(1, 5) = c.fy * y * r4;
    j(0, 6) = c.fx * 2.0 * x * y;
    j(1, 6) = c.fy * (r2 + 2.0 * y * y);
    j(0, 7) = c.fx * (r2 + 2.0 * x * x);
    j(1, 7) = c.fy * 2.0 * x * y;
    j(0, 8) = c.fx * x * r4 * r2;
    j(1, 8) = c.fy * y * r4 * r2;
  }
  return true;
}

bool CameraModel::ProjectFisheyeAnalytic(const Eigen::Vector3d& p_camera, Eigen::Vector2d* uv_px,
                                         ProjectionPointJacobian* d_uv_d_p,
                                         ProjectionParameterJacobian* d_uv_d_parameters) const {
  const CameraIntrinsics& c = intrinsics_;
  const double largest = p_camera.cwiseAbs().maxCoeff();
  if (largest == 0.0) return false;
  // Scale by a power of two (exact) so that the squares below neither overflow nor
  // underflow; the projection depends only on the direction.
  const double to_unit = std::ldexp(1.0, -std::ilogb(largest));
  const Eigen::Vector3d p = p_camera * to_unit;
  const double x = p.x();
  const double y = p.y();
  const double z = p.z();
  const double r2 = x * x + y * y;
  const double r = std::sqrt(r2);
  const double theta = std::atan2(r, z);
  if (!(theta < max_angle_rad_)) return false;

  // (x_d, y_d) = scale * (x, y), with the same branches as ProjectFisheye.
  double scale;
  Eigen::Matrix<double, 2, 3> d_xy_d_d_p;
  // d x_d / d k_i = x * d_scale_d_k[i], likewise for y.
  std::array<double, 4> d_scale_d_k = {0.0, 0.0, 0.0, 0.0};
  if (z > 0.0 && r2 < kFisheyeAxisMaxTan2 * z * z) {
    // The axis limit; d scale / d k_i = theta^(2i+1) / r = O(tan²θ) / z stays 0.
    scale = 1.0 / z;
    d_xy_d_d_p << scale, 0.0, -x * scale * scale,  //
        0.0, scale, -y * scale * scale;
  } else {
    const double theta_d = FisheyeThetaD(c, theta);
    scale = theta_d / r;
    const double cos_phi = x / r;
    const double sin_phi = y / r;
    const double n2 = r2 + z * z;
    // (x_d, y_d) = theta_d (cos phi, sin phi): theta_d changes along the radial direction
    // with d theta / d(x, y, z) = (z cos phi, z sin phi, -r) / n², the azimuth changes
    // across it with d(cos phi, sin phi) / d(x, y) = (sin phi, -cos phi)(sin phi, -cos phi)^T / r.
    const double radial = FisheyeThetaDDerivative(c, theta) * z / n2;
    const double cross = (radial - scale) * cos_phi * sin_phi;
    const double along_z = -FisheyeThetaDDerivative(c, theta) * r / n2;
    d_xy_d_d_p << radial * cos_phi * cos_phi + scale * sin_phi * sin_phi, cross,
        along_z * cos_phi,  //
        cross, radial * sin_phi * sin_phi + scale * cos_phi * cos_phi, along_z * sin_phi;
    const double theta2 = theta * theta;
    double power = theta * theta2 / r;  // theta^(2i+1) / r for k_i, i = 1..4
    for (double& d : d_scale_d_k) {
      d = power;
      power *= theta2;
    }
  }
  const Eigen::Vector2d uv(c.fx * (x * scale) + c.cx, c.fy * (y * scale) + c.cy);
  if (!uv.allFinite()) return false;
  *uv_px = uv;
  if (d_uv_d_p != nullptr) {
    // Chain rule through the scaling p = p_camera * to_unit.
    *d_uv_d_p = Eigen::Vector2d(c.fx * to_unit, c.fy * to_unit).asDiagonal() * d_xy_d_d_p;
  }
  if (d_uv_d_parameters != nullptr) {
    ProjectionParameterJacobian& j = *d_uv_d_parameters;
    j.setZero(2, kFisheyeParameterCount);
    j(0, 0) = x * scale;
    j(1, 1) = y * scale;
    j(0, 2) = 1.0;
    j(1, 3) = 1.0;
    for (int i = 0; i < 4; ++i) {
      j(0, 4 + i) = c.fx * x * d_scale_d_k[i];
      j(1, 4 + i) = c.fy * y * d_scale_d_k[i];
    }
  }
  return true;
}

bool CameraModel::Unproject(const Eigen::Vector2d& uv_px, Eigen::Vector3d* ray_camera) const {
  if (!uv_px.allFinite()) return false;
  const CameraIntrinsics& c = intrinsics_;
  const Eigen::Vector2d xy_d((uv_px.x() - c.cx) / c.fx, (uv_px.y() - c.cy) / c.fy);
  return c.type == CameraModelType::kPinhole ? UnprojectPinhole(xy_d, ray_camera)
                                             : UnprojectFisheye(xy_d, ray_camera);
}

bool CameraModel::UnprojectPinhole(const Eigen::Vector2d& xy_d, Eigen::Vector3d* ray_camera) const {
  const CameraIntrinsics& c = intrinsics_;
  const double max_r2 = max_radius_ * max_radius_;
  // Start on the optical axis, where the distortion is the identity: the first full step
  // goes to xy_d itself. Every accepted step stays inside the valid disc, where the
  // distortion Jacobian is non-singular and the Newton direction descends on |residual|.
  Eigen::Vector2d xy = Eigen::Vector2d::Zero();
  PinholeDistortion d = DistortPinhole(c, xy);
  Eigen::Vector2d residual = d.xy_d - xy_d;
  for (int iteration = 0;; ++iteration) {
    if (residual.norm() <= kResidualUlps * kEps * (d.term_magnitude + xy_d.norm())) break;
    if (iteration == kMaxPinholeIterations) return false;
    const Eigen::Matrix2d& j = d.d_xy_d_d_xy;
    const double det = j.determinant();
    if (!(det > 0.0) || !std::isfinite(det)) return false;
    const Eigen::Vector2d step = -(j.inverse() * residual);
    if (step.norm() <= kStepUlps * kEps * xy.norm()) break;
    double fraction = 1.0;
    bool improved = false;
    for (int halving = 0; halving < kMaxStepHalvings && !improved; ++halving, fraction *= 0.5) {
      const Eigen::Vector2d trial = xy + fraction * step;
      if (!(trial.squaredNorm() < max_r2)) continue;
      const PinholeDistortion trial_d = DistortPinhole(c, trial);
      const Eigen::Vector2d trial_residual = trial_d.xy_d - xy_d;
      if (trial_residual.norm() < residual.norm()) {
        xy = trial;
        d = trial_d;
        residual = trial_residual;
        improved = true;
      }
    }
    // No step inside the valid disc reduces the residual: xy_d has no valid preimage.
    if (!improved) return false;
  }
  *ray_camera = Eigen::Vector3d(xy.x(), xy.y(), 1.0).normalized();
  return true;
}

bool CameraModel::UnprojectFisheye(const Eigen::Vector2d& xy_d, Eigen::Vector3d* ray_camera) const {
  const CameraIntrinsics& c = intrinsics_;
  const double theta_d = xy_d.norm();
  if (theta_d == 0.0) {
    *ray_camera = Eigen::Vector3d::UnitZ();
    return true;
  }
  if (!(theta_d < max_theta_d_)) return false;
  // theta_d(theta) is strictly increasing on [0, max_angle_rad_): keep a bracket [lo, hi]
  // around the root, take Newton steps that stay inside it and at least halve the step
  // before last, bisect otherwise.
  double lo = 0.0;
  double hi = max_angle_rad_;
  // theta_d ~ theta near the axis: a good start, if it lies inside the bracket.
  double theta = theta_d < hi ? theta_d : 0.5 * hi;
  double step_before_last = hi;
  double last_step = hi;
  bool converged = false;
  for (int iteration = 0; iteration < kMaxFisheyeIterations && !converged; ++iteration) {
    const double residual = FisheyeThetaD(c, theta) - theta_d;
    if (std::abs(residual) <= kResidualUlps * kEps * (FisheyeTermMagnitude(c, theta) + theta_d)) {
      converged = true;
      break;
    }
    (residual < 0.0 ? lo : hi) = theta;
    double next = theta - residual / FisheyeThetaDDerivative(c, theta);
    if (!(next > lo && next < hi && std::abs(next - theta) < 0.5 * step_before_last)) {
      next = 0.5 * (lo + hi);
    }
    step_before_last = last_step;
    last_step = std::abs(next - theta);
    theta = next;
    converged = last_step <= kStepUlps * kEps * theta;
  }
  if (!converged) return false;
  const double sin_theta = std::sin(theta);
  *ray_camera = Eigen::Vector3d(sin_theta * xy_d.x() / theta_d, sin_theta * xy_d.y() / theta_d,
                                std::cos(theta));
  return true;
}

}  // namespace linecal
