#include "station/solvers/lane_calibration.h"

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <cmath>
#include <limits>
#include <numbers>
#include <string>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "station/solvers/seed_formulas.h"

namespace linecal {
namespace {

constexpr double kRadToDeg = 180.0 / std::numbers::pi;
// Lines closer than this in direction have no usable intersection: at 0.5 degrees a 1 px
// error of one point moves the vanishing point by hundreds of pixels.
constexpr double kMinLaneAngleRad = 0.5 * std::numbers::pi / 180.0;
// Two marked points of one line closer than this define no direction.
constexpr double kMinPointSpreadPx = 1.0;

// A line n . p = d with unit normal n, fitted by total least squares.
struct ImageLine {
  Eigen::Vector2d n;
  double d = 0;
  double rms_px = 0;
};

Eigen::Matrix3d KMatrix(const CameraIntrinsics& k) {
  Eigen::Matrix3d m;
  m << k.fx, 0, k.cx, 0, k.fy, k.cy, 0, 0, 1;
  return m;
}

std::string Px(const Eigen::Vector2d& p) { return absl::StrFormat("(%.1f, %.1f)", p.x(), p.y()); }

absl::StatusOr<ImageLine> FitLine(const std::vector<Eigen::Vector2d>& points,
                                  const std::string& name) {
  Eigen::Vector2d c = Eigen::Vector2d::Zero();
  for (const Eigen::Vector2d& p : points) c += p;
  c /= static_cast<double>(points.size());
  Eigen::Matrix2d scatter = Eigen::Matrix2d::Zero();
  double spread = 0;
  for (const Eigen::Vector2d& p : points) {
    scatter += (p - c) * (p - c).transpose();
    for (const Eigen::Vector2d& q : points) spread = std::max(spread, (p - q).norm());
  }
  if (spread < kMinPointSpreadPx) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "%s: its points coincide (%.2f px apart at most): a line needs two distinct points", name,
        spread));
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(scatter);  // ascending eigenvalues
  ImageLine line;
  line.n = eig.eigenvectors().col(0);
  line.d = line.n.dot(c);
  line.rms_px = std::sqrt(std::max(0.0, eig.eigenvalues()(0)) / static_cast<double>(points.size()));
  return line;
}

// The undistorted pixel, or an error naming the point.
absl::StatusOr<Eigen::Vector2d> Undistort(const CameraModel& camera, const Eigen::Vector2d& uv,
                                          const std::string& name) {
  Eigen::Vector2d q;
  if (!camera.IsInImage(uv)) {
    return absl::InvalidArgumentError(absl::StrCat(name, " ", Px(uv), ": outside the image"));
  }
  if (!UndistortedPixel(camera, uv, &q)) {
    return absl::InvalidArgumentError(
        absl::StrCat(name, " ", Px(uv), ": no ray in front of the camera through the lens model"));
  }
  return q;
}

// The ray of an undistorted pixel must go down to the ground, i.e. below the horizon.
absl::Status CheckBelowHorizon(const Eigen::Matrix3d& k_inv, const Eigen::Vector3d& up_camera,
                               const Eigen::Vector2d& q, const Eigen::Vector2d& uv,
                               const std::string& name) {
  const Eigen::Vector3d ray = (k_inv * q.homogeneous()).normalized();
  // A ray within 1e-6 rad of the horizon meets the ground beyond any useful distance.
  if (ray.dot(up_camera) > -1e-6) {
    return absl::InvalidArgumentError(absl::StrCat(
        name, " ", Px(uv),
        " is above the horizon: its ray does not reach the ground (check the points and the "
        "camera direction)"));
  }
  return absl::OkStatus();
}

absl::Status Validate(const LaneCalibrationInput& in) {
  if (!(in.camera_height_m > 0 && in.camera_height_m <= 10)) {
    return absl::InvalidArgumentError(
        absl::StrCat("camera_height_m = ", in.camera_height_m, ": must be in (0, 10]"));
  }
  if (!std::isfinite(in.longitudinal_offset_m))
    return absl::InvalidArgumentError("longitudinal_offset_m: must be finite");
  if (!std::isfinite(in.lateral_offset_m))
    return absl::InvalidArgumentError("lateral_offset_m: must be finite");
  if (!(std::abs(in.assumed_roll_rad) <= std::numbers::pi / 4)) {
    return absl::InvalidArgumentError(
        absl::StrCat("roll_deg = ", in.assumed_roll_rad * kRadToDeg, ": must be within [-45, 45]"));
  }
  if (!(in.tolerance_percent > 0 && in.tolerance_percent <= 100)) {
    return absl::InvalidArgumentError(
        absl::StrCat("tolerance_percent = ", in.tolerance_percent, ": must be in (0, 100]"));
  }
  if (in.marked_point &&
      !(in.marked_point->measured_distance_m > 0 && in.marked_point->measured_distance_m < 1e4)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "measured_distance_m = ", in.marked_point->measured_distance_m, ": must be in (0, 10000)"));
  }
  for (double d : in.ranging_distances_m) {
    if (!(d > 0 && d < 1e4))
      return absl::InvalidArgumentError(
          "ranging_distances_m: every distance must be in (0, 10000)");
  }
  if (in.lanes_px.size() < 2) {
    return absl::InvalidArgumentError(
        absl::StrCat("lanes: at least 2 lines needed, got ", in.lanes_px.size()));
  }
  for (size_t i = 0; i < in.lanes_px.size(); ++i) {
    if (in.lanes_px[i].size() < 2) {
      return absl::InvalidArgumentError(
          absl::StrCat("lanes[", i, "]: at least 2 points needed, got ", in.lanes_px[i].size()));
    }
  }
  return absl::OkStatus();
}

// The R_car_camera that maps forward_camera (the direction of +x_car in the camera frame) to
// +x_car and has mounting roll `roll`: its yaw and pitch in closed form (docs/aftersale.md).
Eigen::Matrix3d RotationFromForwardAndRoll(const Eigen::Vector3d& forward_camera, double roll,
                                           bool backward) {
  // R_car_camera forward = e_x  <=>  Rx(roll) R_base forward = Ry(pitch)^T Rz(yaw)^T e_x
  //                                = (cos p cos y, -sin y, sin p cos y).
  const Eigen::Vector3d w =
      Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitX()) * (CameraBaseRotation() * forward_camera);
  // |pitch| < 90 degrees: cos(pitch) > 0, so the sign of cos(yaw) is that of the direction.
  const double s = backward ? -1.0 : 1.0;
  YawPitchRoll a;
  a.roll = roll;
  a.pitch = std::atan2(s * w.z(), s * w.x());
  a.yaw = std::atan2(-w.y(), s * std::hypot(w.x(), w.z()));
  return MountingRotation(a, CameraBaseRotation());
}

}  // namespace

bool GroundPointOfPixel(const CameraModel& camera, const Rigid3d& T_camera_car,
                        const Eigen::Vector2d& uv_px, Eigen::Vector2d* p_ground) {
  Eigen::Vector2d q;
  if (!UndistortedPixel(camera, uv_px, &q)) return false;
  const Eigen::Matrix3d k_inv = KMatrix(camera.intrinsics()).inverse();
  const Eigen::Vector3d up_camera = T_camera_car.RotationMatrix().col(2);
  if (!CheckBelowHorizon(k_inv, up_camera, q, uv_px, "").ok()) return false;
  *p_ground = (GroundHomography(camera.intrinsics(), T_camera_car).inverse() * q.homogeneous())
                  .hnormalized();
  return true;
}

double RelativeRangingError(const CameraModel& camera, const Rigid3d& T_car_camera_true,
                            const Rigid3d& T_car_camera_estimate, const Eigen::Vector2d& p_ground) {
  constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
  Eigen::Vector2d uv, back;
  const Eigen::Vector3d p_camera =
      T_car_camera_true.Inverse() * Eigen::Vector3d(p_ground.x(), p_ground.y(), 0);
  if (!camera.Project(p_camera, &uv) || !camera.IsInImage(uv)) return kNaN;
  if (!GroundPointOfPixel(camera, T_car_camera_estimate.Inverse(), uv, &back)) return kNaN;
  return (back - p_ground).norm() / (p_ground - T_car_camera_true.translation().head<2>()).norm();
}

namespace {

// The lanes' points undistorted (per lane, in input order) and the line fitted to each.
struct LaneLines {
  std::vector<std::vector<Eigen::Vector2d>> undistorted;
  std::vector<ImageLine> lines;
};

// Undistorts every lane point and fits a line to each lane (its RMS into r->lane_fit_rms_px);
// InvalidArgument naming the point or lane that cannot be undistorted or fitted.
absl::StatusOr<LaneLines> FitLanes(const CameraModel& camera, const LaneCalibrationInput& input,
                                   LaneCalibrationResult* r) {
  LaneLines out;
  out.undistorted.resize(input.lanes_px.size());
  for (size_t i = 0; i < input.lanes_px.size(); ++i) {
    for (size_t j = 0; j < input.lanes_px[i].size(); ++j) {
      absl::StatusOr<Eigen::Vector2d> q =
          Undistort(camera, input.lanes_px[i][j], absl::StrCat("lanes[", i, "][", j, "]"));
      if (!q.ok()) return q.status();
      out.undistorted[i].push_back(*q);
    }
    absl::StatusOr<ImageLine> line = FitLine(out.undistorted[i], absl::StrCat("lanes[", i, "]"));
    if (!line.ok()) return line.status();
    out.lines.push_back(*line);
    r->lane_fit_rms_px.push_back(line->rms_px);
  }
  return out;
}

// The vanishing point nearest to all the lines, and its RMS distance from them, into *r;
// InvalidArgument when the lines are too close to parallel to meet.
absl::Status SetVanishingPoint(const std::vector<ImageLine>& lines, LaneCalibrationResult* r) {
  Eigen::Matrix2d a = Eigen::Matrix2d::Zero();
  Eigen::Vector2d b = Eigen::Vector2d::Zero();
  for (const ImageLine& l : lines) {
    a += l.n * l.n.transpose();
    b += l.n * l.d;
  }
  // For two lines at angle t the eigenvalues of sum n n^T are 1 -+ cos t, whose ratio is
  // tan^2(t / 2); for more lines the ratio measures their spread the same way.
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(a);
  const double spread_rad =
      2 * std::atan(std::sqrt(std::max(0.0, eig.eigenvalues()(0)) / eig.eigenvalues()(1)));
  if (spread_rad < kMinLaneAngleRad) {
    return absl::InvalidArgumentError(
        absl::StrFormat("parallel lines: the lane lines are parallel in the image (%.3f deg apart, "
                        "at least %.1f needed), so they "
                        "have no vanishing point",
                        spread_rad * kRadToDeg, kMinLaneAngleRad * kRadToDeg));
  }
  r->vanishing_point_px = a.ldlt().solve(b);
  double sum2 = 0;
  for (const ImageLine& l : lines) sum2 += std::pow(l.n.dot(r->vanishing_point_px) - l.d, 2);
  r->vanishing_point_residual_px = std::sqrt(sum2 / static_cast<double>(lines.size()));
  return absl::OkStatus();
}

// The camera's rotation from x_car (x_camera: +x_car in the camera frame) and the roll line,
// and the roll line's two points undistorted.
struct RollLineFrame {
  Eigen::Matrix3d R_car_camera;
  std::array<Eigen::Vector2d, 2> q;
};

// The rotation that input.roll_line_px (set) gives with x_camera (k: the pinhole matrix);
// InvalidArgument when its points cannot be undistorted, coincide, or the line runs along
// the car.
absl::StatusOr<RollLineFrame> FrameFromRollLine(const CameraModel& camera,
                                                const LaneCalibrationInput& input,
                                                const Eigen::Matrix3d& k,
                                                const Eigen::Vector3d& x_camera) {
  RollLineFrame out;
  std::array<Eigen::Vector2d, 2>& q = out.q;
  for (int e = 0; e < 2; ++e) {
    absl::StatusOr<Eigen::Vector2d> u =
        Undistort(camera, (*input.roll_line_px)[e], absl::StrCat("roll_line[", e, "]"));
    if (!u.ok()) return u.status();
    q[e] = *u;
  }
  if ((q[0] - q[1]).norm() < kMinPointSpreadPx) {
    return absl::InvalidArgumentError(
        "roll_line: its two points coincide: a line needs two distinct points");
  }
  // The plane through the optical centre and the roll line contains y_car, which is also
  // perpendicular to x_car.
  const Eigen::Vector3d plane_normal =
      (k.transpose() * q[0].homogeneous().cross(q[1].homogeneous())).normalized();
  // sin of the angle between x_car and the roll line's plane: 0 for a line through the
  // vanishing point (one along the car), sin(depression angle) for a perpendicular one, 0.027
  // at 50 m ahead of a camera 1.35 m high. Below 0.5 degrees a pixel of error turns the
  // line by degrees.
  if (std::abs(plane_normal.dot(x_camera)) < std::sin(kMinLaneAngleRad)) {
    return absl::InvalidArgumentError(
        "roll_line: it runs (nearly) through the vanishing point, i.e. along the car; it must be "
        "perpendicular to "
        "the car");
  }
  Eigen::Vector3d y_camera = plane_normal.cross(x_camera).normalized();
  Eigen::Vector3d z_camera = x_camera.cross(y_camera);
  // z_car points up, i.e. about -y_camera for an upright camera.
  if (z_camera.y() > 0) {
    y_camera = -y_camera;
    z_camera = -z_camera;
  }
  Eigen::Matrix3d R_camera_car;
  R_camera_car << x_camera, y_camera, z_camera;
  out.R_car_camera = R_camera_car.transpose();
  return out;
}

// Every lane point and roll-line point (undistorted, and as given for the message) below the
// horizon of the camera whose up direction is up_camera; InvalidArgument naming the first
// that is not.
absl::Status CheckPointsBelowHorizon(const Eigen::Matrix3d& k_inv, const Eigen::Vector3d& up_camera,
                                     const LaneCalibrationInput& input, const LaneLines& lanes,
                                     const std::optional<std::array<Eigen::Vector2d, 2>>& roll_q) {
  const std::vector<std::vector<Eigen::Vector2d>>& undistorted = lanes.undistorted;
  for (size_t i = 0; i < undistorted.size(); ++i) {
    for (size_t j = 0; j < undistorted[i].size(); ++j) {
      if (absl::Status s =
              CheckBelowHorizon(k_inv, up_camera, undistorted[i][j], input.lanes_px[i][j],
                                absl::StrCat("lanes[", i, "][", j, "]"));
          !s.ok()) {
        return s;
      }
    }
  }
  if (roll_q) {
    for (int e = 0; e < 2; ++e) {
      if (absl::Status s =
              CheckBelowHorizon(k_inv, up_camera, (*roll_q)[e], (*input.roll_line_px)[e],
                                absl::StrCat("roll_line[", e, "]"));
          !s.ok()) {
        return s;
      }
    }
  }
  return absl::OkStatus();
}

// The distance check of input.marked_point (set) against the ground point the calibration
// puts under it (along: +1 looking forward, -1 backward); InvalidArgument when the point
// cannot be undistorted or lies above the horizon.
absl::StatusOr<LaneDistanceCheck> CheckMarkedPoint(const CameraModel& camera,
                                                   const LaneCalibrationInput& input,
                                                   const Eigen::Matrix3d& k_inv,
                                                   const Rigid3d& T_camera_car, double along) {
  const Eigen::Vector3d up_camera = T_camera_car.RotationMatrix().col(2);
  const LaneMarkedPoint& m = *input.marked_point;
  absl::StatusOr<Eigen::Vector2d> q = Undistort(camera, m.uv_px, "marked_point");
  if (!q.ok()) return q.status();
  if (absl::Status s = CheckBelowHorizon(k_inv, up_camera, *q, m.uv_px, "marked_point"); !s.ok())
    return s;
  Eigen::Vector2d p_ground;
  GroundPointOfPixel(camera, T_camera_car, m.uv_px, &p_ground);
  LaneDistanceCheck c;
  c.measured_distance_m = m.measured_distance_m;
  c.computed_distance_m = along * (p_ground.x() - input.longitudinal_offset_m);
  c.error_percent = 100 * (c.computed_distance_m - c.measured_distance_m) / c.measured_distance_m;
  c.pass = std::abs(c.error_percent) <= input.tolerance_percent;
  return c;
}

}  // namespace

absl::StatusOr<LaneCalibrationResult> CalibrateFromLanes(const LaneCalibrationInput& input) {
  if (absl::Status s = Validate(input); !s.ok()) return s;
  absl::StatusOr<CameraModel> camera = CameraModel::Create(input.intrinsics);
  if (!camera.ok())
    return absl::InvalidArgumentError(absl::StrCat("intrinsics: ", camera.status().message()));

  LaneCalibrationResult r;
  // Lines through the undistorted points; the vanishing point nearest to all of them.
  absl::StatusOr<LaneLines> lanes = FitLanes(*camera, input, &r);
  if (!lanes.ok()) return lanes.status();
  if (absl::Status s = SetVanishingPoint(lanes->lines, &r); !s.ok()) return s;

  const Eigen::Matrix3d k = KMatrix(input.intrinsics);
  const Eigen::Matrix3d k_inv = k.inverse();
  const double along = input.looking_backward ? -1.0 : 1.0;
  // +x_car in the camera frame.
  const Eigen::Vector3d x_camera =
      along * (k_inv * r.vanishing_point_px.homogeneous()).normalized();

  Eigen::Matrix3d R_car_camera;
  std::optional<std::array<Eigen::Vector2d, 2>> roll_q;
  if (input.roll_line_px) {
    absl::StatusOr<RollLineFrame> frame = FrameFromRollLine(*camera, input, k, x_camera);
    if (!frame.ok()) return frame.status();
    roll_q = frame->q;
    R_car_camera = frame->R_car_camera;
    r.roll_from_line = true;
  } else {
    R_car_camera =
        RotationFromForwardAndRoll(x_camera, input.assumed_roll_rad, input.looking_backward);
  }
  r.angles = MountingAngles(R_car_camera, CameraBaseRotation());
  r.T_car_camera = Rigid3d(
      R_car_camera,
      Eigen::Vector3d(input.longitudinal_offset_m, input.lateral_offset_m, input.camera_height_m));
  const Rigid3d T_camera_car = r.T_car_camera.Inverse();
  const Eigen::Vector3d up_camera = T_camera_car.RotationMatrix().col(2);
  if (absl::Status s = CheckPointsBelowHorizon(k_inv, up_camera, input, *lanes, roll_q); !s.ok())
    return s;

  r.ground_homography = GroundHomography(input.intrinsics, T_camera_car);
  r.flat_formula =
      RangingCheckOf(*camera, T_camera_car, r.vanishing_point_px, input.ranging_distances_m);

  if (input.marked_point) {
    absl::StatusOr<LaneDistanceCheck> c =
        CheckMarkedPoint(*camera, input, k_inv, T_camera_car, along);
    if (!c.ok()) return c.status();
    r.distance_check = *c;
  }
  return r;
}

}  // namespace linecal
