#include "station/aftersale/overlay.h"

#include <algorithm>
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

Image8 BirdsEyeImage(const Image8& image, const CameraModel& camera,
                     const LaneCalibrationInput& input, const LaneCalibrationResult& result,
                     const BirdsEyeLayout& layout) {
  const int w = layout.width(), h = layout.height();
  Image8 page(w, h, 0);
  const Eigen::Vector3d c = result.T_car_camera.translation();
  const Rigid3d T_camera_car = result.T_car_camera.Inverse();
  const double along = input.looking_backward ? -1 : 1;
  const CameraIntrinsics& k = camera.intrinsics();
  for (int row = 0; row < h; ++row) {
    for (int col = 0; col < w; ++col) {
      const double ahead = layout.far_m - (row + 0.5) / layout.px_per_m;
      const double left = layout.half_width_m - (col + 0.5) / layout.px_per_m;
      // For a camera looking backward, its left is the car's right.
      const Eigen::Vector3d g(c.x() + along * ahead, c.y() + along * left, 1.0);
      // The ground point in the undistorted image; it must be in front of the camera, which
      // the homography alone cannot tell (q and -q are the same pixel).
      const Eigen::Vector3d q = result.ground_homography * g;
      if ((T_camera_car * Eigen::Vector3d(g.x(), g.y(), 0)).z() <= 0) continue;
      Eigen::Vector2d uv;
      if (!DistortedPixelOf(camera, q.hnormalized(), &uv) || !camera.IsInImage(uv)) continue;
      // Bilinear sample of the stored image.
      const double x = std::clamp(uv.x(), 0.0, k.width - 1.0);
      const double y = std::clamp(uv.y(), 0.0, k.height - 1.0);
      const int x0 = static_cast<int>(x), y0 = static_cast<int>(y);
      const int x1 = std::min(x0 + 1, k.width - 1), y1 = std::min(y0 + 1, k.height - 1);
      const double fx = x - x0, fy = y - y0;
      const double v = (1 - fy) * ((1 - fx) * image.at(x0, y0) + fx * image.at(x1, y0)) +
                       fy * ((1 - fx) * image.at(x0, y1) + fx * image.at(x1, y1));
      page.at(col, row) = static_cast<std::uint8_t>(std::lround(v));
    }
  }
  return page;
}

RgbImage BirdsEyePicture(const Image8& image, const CameraModel& camera,
                         const LaneCalibrationInput& input, const LaneCalibrationResult& result,
                         const BirdsEyeLayout& layout) {
  const Image8 grey = BirdsEyeImage(image, camera, input, result, layout);
  const int w = grey.width, h = grey.height;
  RgbImage img(w, h);
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      std::uint8_t* p = img.at(x, y);
      p[0] = p[1] = p[2] = grey.at(x, y);
    }
  }
  // Whole rows and columns: the grid's lines fall on pixel centres at the page's scale.
  const auto paint = [&img](int x, int y) {
    if (x < 0 || y < 0 || x >= img.width || y >= img.height) return;
    std::copy(kBirdsEyeGridColour.begin(), kBirdsEyeGridColour.end(), img.at(x, y));
  };
  for (double d = 5; d < layout.far_m; d += 5) {
    const int row = static_cast<int>(std::lround((layout.far_m - d) * layout.px_per_m));
    for (int x = 0; x < w; ++x) paint(x, row);
  }
  for (double y = -layout.half_width_m + 1; y < layout.half_width_m; y += 1) {
    const int col = static_cast<int>(std::lround((layout.half_width_m - y) * layout.px_per_m));
    for (int row = 0; row < h; ++row) paint(col, row);
  }
  return img;
}

}  // namespace linecal
