#pragma once
// The one rigid-pose type of linecal, and mounting angles (docs/conventions.md).
//
// A Rigid3d named T_target_source maps points of frame `source` into frame `target`:
//   p_car = T_car_camera * p_camera,   T_car_lidar = T_car_station * T_station_lidar.
// Rotation is a unit quaternion, translation is in metres. Never pass raw quaternion
// coefficient arrays between modules: Eigen stores (x, y, z, w), Ceres (w, x, y, z).
//
// Header-only so that detectors/ (which may use only the standard library and Eigen) and
// everything above it share one type. All functions are O(1) and allocate nothing.

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cmath>

namespace linecal {

class Rigid3d {
 public:
  // Identity.
  Rigid3d() : rotation_(Eigen::Quaterniond::Identity()), translation_(Eigen::Vector3d::Zero()) {}

  // `rotation` need not be normalised; it is normalised here. A zero quaternion is a caller
  // bug (it has no rotation); it yields NaNs rather than a silent identity.
  Rigid3d(const Eigen::Quaterniond& rotation, const Eigen::Vector3d& translation)
      : rotation_(rotation.normalized()), translation_(translation) {}

  // From a rotation matrix (re-orthonormalised through the quaternion) and a translation.
  Rigid3d(const Eigen::Matrix3d& rotation, const Eigen::Vector3d& translation)
      : Rigid3d(Eigen::Quaterniond(rotation), translation) {}

  // From a 4x4 homogeneous matrix [R t; 0 0 0 1]. The last row is not checked.
  static Rigid3d FromMatrix(const Eigen::Matrix4d& m) {
    return Rigid3d(Eigen::Matrix3d(m.topLeftCorner<3, 3>()),
                   Eigen::Vector3d(m.topRightCorner<3, 1>()));
  }

  static Rigid3d Translation(const Eigen::Vector3d& t) {
    return Rigid3d(Eigen::Quaterniond::Identity(), t);
  }

  const Eigen::Quaterniond& rotation() const { return rotation_; }
  const Eigen::Vector3d& translation() const { return translation_; }
  Eigen::Matrix3d RotationMatrix() const { return rotation_.toRotationMatrix(); }

  Eigen::Matrix4d Matrix() const {
    Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
    m.topLeftCorner<3, 3>() = RotationMatrix();
    m.topRightCorner<3, 1>() = translation_;
    return m;
  }

  // T_source_target from T_target_source.
  Rigid3d Inverse() const {
    const Eigen::Quaterniond inv = rotation_.conjugate();
    return Rigid3d(inv, -(inv * translation_));
  }

  // T_a_c = T_a_b * T_b_c.
  Rigid3d operator*(const Rigid3d& rhs) const {
    return Rigid3d(rotation_ * rhs.rotation_, rotation_ * rhs.translation_ + translation_);
  }

  // p_target = T_target_source * p_source.
  Eigen::Vector3d operator*(const Eigen::Vector3d& p) const { return rotation_ * p + translation_; }

 private:
  Eigen::Quaterniond rotation_;
  Eigen::Vector3d translation_;
};

// [v]x, the matrix of the cross product: Skew(v) * w == v.cross(w). The derivative of a
// rotated point under a small rotation: d(exp(δθ) p)/dδθ = -Skew(p) at δθ = 0. O(1).
inline Eigen::Matrix3d Skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d s;
  s << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return s;
}

// Mounting angles in radians: R_car_sensor = Rz(yaw) * Ry(pitch) * Rx(roll) * R_base.
struct YawPitchRoll {
  double yaw = 0.0;
  double pitch = 0.0;
  double roll = 0.0;
};

// Rz(yaw) * Ry(pitch) * Rx(roll).
inline Eigen::Matrix3d RotationFromYawPitchRoll(const YawPitchRoll& a) {
  return (Eigen::AngleAxisd(a.yaw, Eigen::Vector3d::UnitZ()) *
          Eigen::AngleAxisd(a.pitch, Eigen::Vector3d::UnitY()) *
          Eigen::AngleAxisd(a.roll, Eigen::Vector3d::UnitX()))
      .toRotationMatrix();
}

// Inverse of RotationFromYawPitchRoll, with pitch in [-pi/2, pi/2] and yaw, roll in
// (-pi, pi]. At pitch = +-pi/2 (gimbal lock) only yaw -+ roll is defined; roll is then 0.
inline YawPitchRoll YawPitchRollFromRotation(const Eigen::Matrix3d& r) {
  YawPitchRoll a;
  // r(2,0) = -sin(pitch); cos(pitch) from the norm of the rest of its column, which stays
  // accurate near +-90 degrees where asin(-r(2,0)) would lose half the digits.
  const double cos_pitch = std::hypot(r(0, 0), r(1, 0));
  a.pitch = std::atan2(-r(2, 0), cos_pitch);
  // Below this cos(pitch) the yaw and roll columns carry only rounding noise.
  constexpr double kGimbalLockCos = 1e-12;
  if (cos_pitch > kGimbalLockCos) {
    a.yaw = std::atan2(r(1, 0), r(0, 0));
    a.roll = std::atan2(r(2, 1), r(2, 2));
  } else {
    a.yaw = std::atan2(-r(0, 1), r(1, 1));
    a.roll = 0.0;
  }
  return a;
}

// R_base of a camera (docs/conventions.md): maps z_camera to x_car, x_camera to -y_car and
// y_camera to -z_car, so a camera looking straight forward has yaw = pitch = roll = 0.
inline Eigen::Matrix3d CameraBaseRotation() {
  Eigen::Matrix3d r;
  // Columns are the camera axes expressed in the car frame.
  r << 0, 0, 1,  //
      -1, 0, 0,  //
      0, -1, 0;
  return r;
}

// Mounting angles of a sensor whose zero-angle orientation is `r_base`.
inline YawPitchRoll MountingAngles(const Eigen::Matrix3d& r_car_sensor,
                                   const Eigen::Matrix3d& r_base) {
  return YawPitchRollFromRotation(r_car_sensor * r_base.transpose());
}

// R_car_sensor from mounting angles and the sensor's zero-angle orientation.
inline Eigen::Matrix3d MountingRotation(const YawPitchRoll& a, const Eigen::Matrix3d& r_base) {
  return RotationFromYawPitchRoll(a) * r_base;
}

}  // namespace linecal
