#include "station/aftersale/overlay.h"

#include <cmath>
#include <numbers>

#include "station/solvers/seed_formulas.h"

namespace linecal {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

// The ground line from a to b (car frame, z = 0) through the estimated pose and the lens.
ImagePolyline GroundLine(const CameraModel& camera, const Rigid3d& T_camera_car,
                         const Eigen::Vector2d& a, const Eigen::Vector2d& b, int segments) {
  ImagePolyline out;
  for (int i = 0; i <= segments; ++i) {
    const Eigen::Vector2d g = a + (b - a) * (static_cast<double>(i) / segments);
    Eigen::Vector2d uv;
    const Eigen::Vector3d p = T_camera_car * Eigen::Vector3d(g.x(), g.y(), 0);
    if (p.z() > 0 && camera.Project(p, &uv) && camera.IsInImage(uv)) {
      out.emplace_back(uv);
    } else {
      out.emplace_back(std::nullopt);
    }
  }
  return out;
}

}  // namespace

bool DistortedPixelOf(const CameraModel& camera, const Eigen::Vector2d& q, Eigen::Vector2d* uv) {
  const CameraIntrinsics& k = camera.intrinsics();
  return camera.Project(Eigen::Vector3d((q.x() - k.cx) / k.fx, (q.y() - k.cy) / k.fy, 1.0), uv);
}

LaneOverlay LaneOverlayOf(const CameraModel& camera, const LaneCalibrationInput& in,
                          const LaneCalibrationResult& r, const LaneOverlayOptions& options) {
  LaneOverlay out;
  const int n = options.segments;
  const Rigid3d T_camera_car = r.T_car_camera.Inverse();
  const Eigen::Vector3d c = r.T_car_camera.translation();
  const double along = in.looking_backward ? -1 : 1;
  for (int d = 5; d <= 50; d += 5) {
    out.ground_grid.push_back(GroundLine(camera, T_camera_car, {c.x() + along * d, c.y() - 5},
                                         {c.x() + along * d, c.y() + 5}, n));
  }
  for (int y = -5; y <= 5; ++y) {
    out.ground_grid.push_back(GroundLine(camera, T_camera_car, {c.x() + along * 2, c.y() + y},
                                         {c.x() + along * 50, c.y() + y}, n));
  }
  const Eigen::Matrix3d R_camera_car = T_camera_car.RotationMatrix();
  for (int a = -60; a <= 60; ++a) {
    const Eigen::Vector3d dir =
        R_camera_car * Eigen::Vector3d(along * std::cos(a * kDeg), std::sin(a * kDeg), 0);
    Eigen::Vector2d uv;
    out.horizon.push_back(dir.z() > 0 && camera.Project(dir, &uv) ? std::optional(uv)
                                                                  : std::nullopt);
  }
  for (const std::vector<Eigen::Vector2d>& points : in.lanes_px) {
    // From the point farthest from the vanishing point (the nearest on the ground).
    Eigen::Vector2d near_q = r.vanishing_point_px;
    for (const Eigen::Vector2d& uv : points) {
      Eigen::Vector2d q;
      if (UndistortedPixel(camera, uv, &q) &&
          (q - r.vanishing_point_px).norm() > (near_q - r.vanishing_point_px).norm()) {
        near_q = q;
      }
    }
    ImagePolyline line;
    for (int i = 0; i <= n; ++i) {
      Eigen::Vector2d uv;
      const Eigen::Vector2d q = near_q + (r.vanishing_point_px - near_q) * (double(i) / n);
      line.push_back(DistortedPixelOf(camera, q, &uv) ? std::optional(uv) : std::nullopt);
    }
    out.lane_lines.push_back(std::move(line));
  }
  Eigen::Vector2d vp_uv;
  if (DistortedPixelOf(camera, r.vanishing_point_px, &vp_uv)) out.vanishing_point_uv = vp_uv;
  return out;
}

}  // namespace linecal
