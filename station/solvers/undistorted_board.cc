#include "station/solvers/undistorted_board.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>
#include <vector>

#include "absl/strings/str_cat.h"
#include "detectors/common/homography.h"

namespace linecal {

absl::Status UndistortedBoardOptions::Validate() const {
  // Residuals of 100 px mean no board at all: a larger bound is a mistake.
  if (!(max_homography_rms_px > 0.0 && max_homography_rms_px <= 100.0)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "max_homography_rms_px = ", max_homography_rms_px, ": must be within (0, 100]"));
  }
  if (const std::string_view field = pnp.Validate(); !field.empty()) {
    return absl::InvalidArgumentError(absl::StrCat("pnp.", std::string(field), ": out of range"));
  }
  return absl::OkStatus();
}

absl::StatusOr<UndistortedBoard> CheckBoardUndistorted(const CameraModel& camera,
                                                       std::span<const DetectedFeature> features,
                                                       const UndistortedBoardOptions& options) {
  if (absl::Status s = options.Validate(); !s.ok()) return s;
  UndistortedBoard result;
  const std::size_t n = features.size();
  result.points = static_cast<int>(n);
  result.homography_rms_px = std::numeric_limits<double>::infinity();
  result.homography_max_px = std::numeric_limits<double>::infinity();
  // A homography needs four points.
  if (n < 4) return result;

  std::vector<Eigen::Vector3d> rays(n);
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  for (std::size_t i = 0; i < n; ++i) {
    if (!camera.Unproject(features[i].uv_px, &rays[i])) return result;
    sum += rays[i];
  }
  // Unit rays of one board seen from its front side never cancel out; a sum this short means
  // rays spread over a whole hemisphere, which no board gives.
  if (sum.norm() < 1e-6 * static_cast<double>(n)) return result;
  // The virtual pinhole: its z along the mean ray.
  const Eigen::Matrix3d R_virtual_camera =
      Eigen::Quaterniond::FromTwoVectors(sum.normalized(), Eigen::Vector3d::UnitZ())
          .toRotationMatrix();
  const double f_px = 0.5 * (camera.intrinsics().fx + camera.intrinsics().fy);
  std::vector<Eigen::Vector2d> p_board(n);
  std::vector<Eigen::Vector2d> uv_virtual_px(n);
  for (std::size_t i = 0; i < n; ++i) {
    const Eigen::Vector3d ray_virtual = R_virtual_camera * rays[i];
    if (ray_virtual.z() <= 0.0) return result;
    p_board[i] = features[i].p_board;
    uv_virtual_px[i] = f_px * ray_virtual.head<2>() / ray_virtual.z();
  }
  const std::optional<HomographyFit> fit = FitHomography(p_board, uv_virtual_px);
  if (!fit.has_value()) return result;

  double sum_sq = 0.0;
  double max_px = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    const Eigen::Vector2d uv_fit = ApplyHomography(fit->H, p_board[i]) / f_px;
    const Eigen::Vector3d p_camera = R_virtual_camera.transpose() * uv_fit.homogeneous();
    Eigen::Vector2d uv_px;
    if (!camera.Project(p_camera, &uv_px)) return result;
    const double r = (uv_px - features[i].uv_px).norm();
    sum_sq += r * r;
    max_px = std::max(max_px, r);
  }
  result.homography_rms_px = std::sqrt(sum_sq / static_cast<double>(n));
  result.homography_max_px = max_px;
  if (result.homography_rms_px > options.max_homography_rms_px) return result;

  std::vector<PnpCorrespondence> points(n);
  for (std::size_t i = 0; i < n; ++i) {
    points[i].p_object = Eigen::Vector3d(features[i].p_board.x(), features[i].p_board.y(), 0.0);
    points[i].uv_px = features[i].uv_px;
  }
  absl::StatusOr<PnpResult> pose = SolvePnp(camera, points, options.pnp);
  if (!pose.ok()) return pose.status();
  result.verified = true;
  result.pose = *std::move(pose);
  return result;
}

}  // namespace linecal
