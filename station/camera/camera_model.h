#pragma once
// Camera projection models (docs/conventions.md, "Camera models"):
//   kPinhole: pinhole with Brown–Conrady distortion k1, k2, p1, p2, k3 (OpenCV's
//             cv::projectPoints parameterisation, no skew, no thin-prism or tilt terms);
//   kFisheye: Kannala–Brandt with k1..k4 (OpenCV's cv::fisheye parameterisation, no skew).
//
// Frames and units: p_camera is a point in the camera frame (x right, y down, z along the
// optical axis); projection depends only on its direction, so any length unit works.
// uv_px are image coordinates in pixels, u right, v down, with the centre of the top-left
// pixel at (0, 0). A ray is a unit vector in the camera frame.
//
// The projection of each model is one-to-one only up to a model-specific angle from the
// optical axis, beyond which the distortion polynomial folds back (two rays on one pixel).
// CameraModel computes that angle once, refuses to project rays beyond it and refuses to
// unproject pixels whose ray would lie beyond it (max_angle_rad()).
//
// Besides CameraModel (analytic Jacobians, the fast path), the header holds the projection
// as plain templates on the scalar type (ProjectPinhole, ProjectFisheye) so that solvers can
// differentiate through it with ceres::Jet. Both compute the same formulas.

#include <Eigen/Core>
#include <limits>

#include "absl/status/status.h"
#include "absl/status/statusor.h"

namespace linecal {

enum class CameraModelType { kPinhole, kFisheye };

// "pinhole", "fisheye"; "unknown" for a value outside the enum. For messages and files.
const char* CameraModelTypeName(CameraModelType type);

// Length of the parameter vector of each model (see CameraParameterName for the order).
inline constexpr int kPinholeParameterCount = 9;
inline constexpr int kFisheyeParameterCount = 8;
inline constexpr int kMaxCameraParameterCount = 9;

// The intrinsics of one camera. Plain data; check with Validate() before use.
struct CameraIntrinsics {
  CameraModelType type = CameraModelType::kPinhole;
  // Image size in pixels, 1..kMaxImageSide.
  int width = 0;
  int height = 0;
  // Focal lengths in pixels (> 0) and principal point in pixels, inside the image area
  // [-0.5, width - 0.5] x [-0.5, height - 0.5].
  double fx = 0.0;
  double fy = 0.0;
  double cx = 0.0;
  double cy = 0.0;
  // Distortion, dimensionless, on normalised coordinates (pinhole) or on the angle in
  // radians (fisheye). Pinhole uses k1, k2, k3, p1, p2 and needs k4 = 0; fisheye uses
  // k1..k4 and needs p1 = p2 = 0.
  double k1 = 0.0;
  double k2 = 0.0;
  double k3 = 0.0;
  double k4 = 0.0;
  double p1 = 0.0;
  double p2 = 0.0;

  // OK, or InvalidArgument whose message starts with the name of the first bad field, e.g.
  // "fx = -3: must be finite and > 0". O(1).
  absl::Status Validate() const;
};

// The parameter vector that solvers optimise and the templated projections read:
//   kPinhole: fx fy cx cy k1 k2 p1 p2 k3   (OpenCV's distortion order)
//   kFisheye: fx fy cx cy k1 k2 k3 k4
// Fixed capacity, so it never allocates.
using CameraParameters =
    Eigen::Matrix<double, Eigen::Dynamic, 1, Eigen::ColMajor, kMaxCameraParameterCount, 1>;

// kPinholeParameterCount or kFisheyeParameterCount; 0 for a value outside the enum.
int CameraParameterCount(CameraModelType type);

// Name of parameter `index` of the vector above ("fx", "k1", ...); "" if out of range.
const char* CameraParameterName(CameraModelType type, int index);

// The parameter vector of `intrinsics` (length CameraParameterCount(intrinsics.type)).
CameraParameters ToCameraParameters(const CameraIntrinsics& intrinsics);

// Inverse of ToCameraParameters. `parameters` holds CameraParameterCount(type) values and is
// only read. The result is not validated.
CameraIntrinsics CameraIntrinsicsFromParameters(CameraModelType type, int width, int height,
                                                const double* parameters);

// Below this tan²(angle from the optical axis) ProjectFisheye uses the axis limit
// theta_d / r = 1 / z instead of atan2(r, z) / r, which is 0/0 on the axis and whose sqrt has
// an infinite derivative there. The limit neglects (k1 - 1/3) tan²θ + O(tan⁴θ) relative,
// below 1e-16 (half an ulp) for any |k1| < 100; above the limit atan2 and sqrt are accurate.
inline constexpr double kFisheyeAxisMaxTan2 = 1e-18;

// Pinhole projection of p_camera[0..2] with parameters[0..8] (order above) into uv_px[0..1].
// T is double or a ceres::Jet. No checks: the caller makes sure that the point is inside the
// valid region (CameraModel::Project decides that); for z <= 0 the result is meaningless.
template <typename T>
void ProjectPinhole(const T* parameters, const T* p_camera, T* uv_px) {
  const T x = p_camera[0] / p_camera[2];
  const T y = p_camera[1] / p_camera[2];
  const T& k1 = parameters[4];
  const T& k2 = parameters[5];
  const T& p1 = parameters[6];
  const T& p2 = parameters[7];
  const T& k3 = parameters[8];
  const T xx = x * x;
  const T yy = y * y;
  const T xy = x * y;
  const T r2 = xx + yy;
  const T radial = T(1.0) + r2 * (k1 + r2 * (k2 + r2 * k3));
  const T x_d = x * radial + T(2.0) * p1 * xy + p2 * (r2 + T(2.0) * xx);
  const T y_d = y * radial + p1 * (r2 + T(2.0) * yy) + T(2.0) * p2 * xy;
  uv_px[0] = parameters[0] * x_d + parameters[2];
  uv_px[1] = parameters[1] * y_d + parameters[3];
}

// Kannala–Brandt projection of p_camera[0..2] with parameters[0..7] (order above) into
// uv_px[0..1]. T is double or a ceres::Jet. No checks: the caller makes sure that the point
// is inside the valid region (CameraModel::Project decides that); on the negative optical
// axis the result is NaN.
template <typename T>
void ProjectFisheye(const T* parameters, const T* p_camera, T* uv_px) {
  using std::atan2;
  using std::sqrt;
  const T& x = p_camera[0];
  const T& y = p_camera[1];
  const T& z = p_camera[2];
  const T& k1 = parameters[4];
  const T& k2 = parameters[5];
  const T& k3 = parameters[6];
  const T& k4 = parameters[7];
  const T r2 = x * x + y * y;
  // theta_d / r, the factor from (x, y) to the distorted normalised coordinates.
  T scale;
  if (z > T(0.0) && r2 < T(kFisheyeAxisMaxTan2) * z * z) {
    scale = T(1.0) / z;
  } else {
    const T r = sqrt(r2);
    const T theta = atan2(r, z);
    const T theta2 = theta * theta;
    const T theta_d =
        theta * (T(1.0) + theta2 * (k1 + theta2 * (k2 + theta2 * (k3 + theta2 * k4))));
    scale = theta_d / r;
  }
  uv_px[0] = parameters[0] * (x * scale) + parameters[2];
  uv_px[1] = parameters[1] * (y * scale) + parameters[3];
}

// d(u, v) / d(p_camera), row-major like a Ceres Jacobian block.
using ProjectionPointJacobian = Eigen::Matrix<double, 2, 3, Eigen::RowMajor>;
// d(u, v) / d(parameters), 2 x CameraParameterCount(type), parameter order as above.
using ProjectionParameterJacobian =
    Eigen::Matrix<double, 2, Eigen::Dynamic, Eigen::RowMajor, 2, kMaxCameraParameterCount>;

// A validated camera with its valid region precomputed. Cheap to copy (about 200 bytes);
// immutable and thread-safe.
class CameraModel {
 public:
  // Validates `intrinsics` (the same status as CameraIntrinsics::Validate on failure) and
  // finds the valid region: O(1), one eigen decomposition of a matrix of at most 6 x 6.
  static absl::StatusOr<CameraModel> Create(const CameraIntrinsics& intrinsics);

  const CameraIntrinsics& intrinsics() const { return intrinsics_; }
  CameraModelType type() const { return intrinsics_.type; }
  // The parameter vector (ToCameraParameters of the intrinsics).
  const CameraParameters& parameters() const { return parameters_; }

  // The valid region: rays strictly less than this angle (radians) from the optical axis.
  // At most pi/2 for a pinhole (a point needs z > 0) and at most pi for a fisheye (the
  // negative axis has no azimuth). Inside it the projection is one-to-one:
  //  - fisheye: theta_d(theta) is strictly increasing, i.e. max_angle_rad is the first
  //    positive root of d theta_d / d theta = 1 + 3 k1 θ² + 5 k2 θ⁴ + 7 k3 θ⁶ + 9 k4 θ⁸;
  //  - pinhole: on the disc r < tan(max_angle_rad) of undistorted normalised coordinates the
  //    symmetric part of the distortion's 2x2 Jacobian is positive definite, which makes the
  //    distortion one-to-one on the disc. Its eigenvalues are at least
  //    min(1 + k1 r² + k2 r⁴ + k3 r⁶, 1 + 3 k1 r² + 5 k2 r⁴ + 7 k3 r⁶) - 6 |(p1, p2)| r, and
  //    the radius is the first positive root of that bound.
  // The valid region does not depend on the image size: it may end inside the image (a bad
  // calibration) or far outside it.
  double max_angle_rad() const { return max_angle_rad_; }

  // Projects p_camera (any length unit, camera frame) to uv_px. Returns false, and leaves
  // all outputs untouched, for a non-finite point, the origin, or a point outside the valid
  // region (for a pinhole this includes every point with z <= 0). Points projecting outside
  // the image are projected: use IsInImage to test that.
  // Optional outputs (nullptr to skip): d_uv_d_p, the 2x3 Jacobian in pixels per unit of
  // p_camera; d_uv_d_parameters, the 2xN Jacobian with respect to parameters().
  // Cost: about 20 ns, 60 ns for a fisheye (atan2); Jacobians add about 20 ns; no allocation.
  bool Project(const Eigen::Vector3d& p_camera, Eigen::Vector2d* uv_px,
               ProjectionPointJacobian* d_uv_d_p = nullptr,
               ProjectionParameterJacobian* d_uv_d_parameters = nullptr) const;

  // The unit ray in the camera frame that projects to uv_px. Fisheye rays may point more
  // than 90 degrees away from the optical axis (z < 0). Returns false, leaving *ray_camera
  // untouched, for non-finite uv_px or when the ray would lie outside the valid region.
  // Inverts the distortion by Newton's method, to double precision: the pinhole by a damped
  // 2-D Newton iteration started on the axis that stays inside the valid disc, the fisheye
  // by a 1-D Newton iteration on theta safeguarded by bisection. Both stop when the residual
  // reaches the rounding bound of evaluating the distortion or the step falls below a few
  // ulps of the solution. Cost: typically 3-6 iterations, 0.1-0.25 us; a pixel without a
  // valid ray gives up after at most 50 (2-D, a few us) or 100 (1-D) iterations; no
  // allocation.
  bool Unproject(const Eigen::Vector2d& uv_px, Eigen::Vector3d* ray_camera) const;

  // True if uv_px lies on the image area [-0.5, width - 0.5] x [-0.5, height - 0.5] (pixel
  // centres are integers, each pixel extends half a pixel around its centre).
  bool IsInImage(const Eigen::Vector2d& uv_px) const;

 private:
  explicit CameraModel(const CameraIntrinsics& intrinsics);

  bool ProjectPinholeAnalytic(const Eigen::Vector3d& p_camera, Eigen::Vector2d* uv_px,
                              ProjectionPointJacobian* d_uv_d_p,
                              ProjectionParameterJacobian* d_uv_d_parameters) const;
  bool ProjectFisheyeAnalytic(const Eigen::Vector3d& p_camera, Eigen::Vector2d* uv_px,
                              ProjectionPointJacobian* d_uv_d_p,
                              ProjectionParameterJacobian* d_uv_d_parameters) const;
  bool UnprojectPinhole(const Eigen::Vector2d& xy_d, Eigen::Vector3d* ray_camera) const;
  bool UnprojectFisheye(const Eigen::Vector2d& xy_d, Eigen::Vector3d* ray_camera) const;

  CameraIntrinsics intrinsics_;
  CameraParameters parameters_;
  double max_angle_rad_ = 0.0;
  // Pinhole: tan(max_angle_rad_), the radius of the valid disc of undistorted normalised
  // coordinates (infinite when the distortion never folds).
  double max_radius_ = std::numeric_limits<double>::infinity();
  // Fisheye: theta_d(max_angle_rad_), the largest distorted radius.
  double max_theta_d_ = 0.0;
};

}  // namespace linecal
