#include "station/solvers/seed_formulas.h"

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <cmath>
#include <limits>
#include <map>

#include "absl/strings/str_cat.h"
#include "detectors/common/homography.h"

namespace linecal {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
// The car axis must cross the board plane at more than ~6 deg: nearer to parallel, the point
// ahead on the board is far off the print and the vanishing point a long extrapolation.
constexpr double kMinAxisDotNormal = 0.1;
// Board y must point upward (within 60 deg) for "straight below a pattern group" to be a
// point on the ground.
constexpr double kMinBoardUpZ = 0.5;
// The vertical board's columns are the car's vertical lines only if its y axis is: a tilt
// of 1e-4 rad (0.006 deg) is the roll error it would cause at most.
constexpr double kMaxVerticalTiltRad = 1e-4;
constexpr int kMinFeaturesPerGroup = 4;
constexpr int kMinCornersPerLine = 3;
constexpr int kMinLines = 2;

BoardMethodResult Refuse(BoardMethodResult r, const char* reason, std::string message) {
  r.valid = false;
  r.reason = reason;
  r.message = std::move(message);
  return r;
}

VerticalBoardRoll RefuseRoll(const char* reason, std::string message) {
  VerticalBoardRoll r;
  r.reason = reason;
  r.message = std::move(message);
  return r;
}

}  // namespace

Eigen::Matrix3d PinholeMatrix(const CameraIntrinsics& k) {
  Eigen::Matrix3d m;
  m << k.fx, 0, k.cx, 0, k.fy, k.cy, 0, 0, 1;
  return m;
}

bool UndistortedPixel(const CameraModel& camera, const Eigen::Vector2d& uv_px,
                      Eigen::Vector2d* undistorted_px) {
  Eigen::Vector3d ray;
  // Rays at or beyond 90 degrees (fisheye) have no point in the undistorted image.
  if (!camera.Unproject(uv_px, &ray) || !(ray.z() > 1e-9)) return false;
  *undistorted_px = (PinholeMatrix(camera.intrinsics()) * ray).hnormalized();
  return true;
}

Eigen::Vector2d FlatGroundRange(const CameraIntrinsics& k, const Eigen::Vector2d& vp, double h,
                                const Eigen::Vector2d& uv) {
  const double below = uv.y() - vp.y();
  if (!(below > 0)) return {kNaN, kNaN};
  const double d_lon = h * k.fy / below;
  return {d_lon, d_lon * (vp.x() - uv.x()) / k.fx};
}

BoardMethodResult SolveBoardMethod(const CameraModel& camera, const Board& board,
                                   const Rigid3d& T_car_board, const Eigen::Vector3d& c, int along,
                                   std::span<const DetectedFeature> features) {
  BoardMethodResult r;
  if (board.type() != BoardType::kChessboard) {
    return Refuse(r, "not_a_chessboard",
                  absl::StrCat("the board method needs the wide chessboard, not a ", board.name()));
  }
  if (along != 1 && along != -1) {
    return Refuse(r, "not_looking_along_car",
                  "the board method needs a camera looking along the car");
  }
  std::vector<Eigen::Vector2d> src, dst;
  int left = 0, right = 0;
  for (const DetectedFeature& f : features) {
    Eigen::Vector2d u;
    if (!UndistortedPixel(camera, f.uv_px, &u)) continue;
    src.push_back(f.p_board);
    dst.push_back(u);
    (f.p_board.x() < 0 ? left : right)++;
  }
  if (left < kMinFeaturesPerGroup || right < kMinFeaturesPerGroup) {
    return Refuse(r, "too_few_features",
                  absl::StrCat(left, " corners of the left pattern group and ", right,
                               " of the right one, ", kMinFeaturesPerGroup, " of each needed"));
  }
  const std::optional<HomographyFit> fit = FitHomography(src, dst);
  if (!fit)
    return Refuse(r, "homography_failed",
                  "no board-to-image homography through the chessboard's corners");
  r.H_image_board = fit->H;
  r.homography_rms_px = fit->rms_residual;

  // The point of the board plane straight ahead of the camera along the car axis.
  const Eigen::Matrix3d R = T_car_board.RotationMatrix();
  const Eigen::Vector3d b = T_car_board.translation();
  const Eigen::Vector3d axis = along * Eigen::Vector3d::UnitX();
  const Eigen::Vector3d n = R.col(2);
  const double cross = n.dot(axis);
  if (std::abs(cross) < kMinAxisDotNormal) {
    return Refuse(r, "axis_parallel_to_board",
                  "the car axis through the camera runs nearly in the board plane");
  }
  const double s = n.dot(b - c) / cross;
  if (!(s > 0))
    return Refuse(r, "board_behind_camera",
                  "the board is not ahead of the camera along the car axis");
  r.board_point_ahead_m = (T_car_board.Inverse() * (c + s * axis)).head<2>();
  r.vanishing_point_px = ApplyHomography(r.H_image_board, r.board_point_ahead_m);

  // A and B: on the ground straight below the centres of the two pattern groups.
  if (R(2, 1) < kMinBoardUpZ)
    return Refuse(r, "board_not_upright", "the chessboard's y axis does not point up");
  Eigen::Vector2d centre[2] = {Eigen::Vector2d::Zero(), Eigen::Vector2d::Zero()};
  int count[2] = {0, 0};
  for (const BoardFeature& f : board.features()) {
    const int g = f.p_board.x() < 0 ? 0 : 1;
    centre[g] += f.p_board;
    ++count[g];
  }
  const double h = c.z();
  for (int g = 0; g < 2; ++g) {
    const double gx = centre[g].x() / count[g];
    const Eigen::Vector2d foot(gx, -(b.z() + R(2, 0) * gx) / R(2, 1));
    r.ground_points_px.push_back(ApplyHomography(r.H_image_board, foot));
  }
  for (int g = 0; g < 2; ++g)
    r.ground_points_px.push_back(0.5 * (r.ground_points_px[g] + r.vanishing_point_px));

  // The levelled frame: the horizon through vp and the image of the board's x axis (a
  // horizontal direction: the board stands upright), the ground normal N = K^T horizon (up:
  // A is below the horizon), F the viewing direction along the car, L = N x F its left.
  const Eigen::Matrix3d K = PinholeMatrix(camera.intrinsics());
  const Eigen::Matrix3d K_inv = K.inverse();
  const Eigen::Vector3d board_x_image = r.H_image_board.col(0);
  Eigen::Vector3d N =
      (K.transpose() * r.vanishing_point_px.homogeneous().cross(board_x_image)).normalized();
  if (N.dot(K_inv * r.ground_points_px[0].homogeneous()) > 0) N = -N;
  const Eigen::Vector3d F_raw = K_inv * r.vanishing_point_px.homogeneous();
  const Eigen::Vector3d F = (F_raw - F_raw.dot(N) * N).normalized();
  const Eigen::Vector3d L = N.cross(F);
  for (const Eigen::Vector2d& p : r.ground_points_px) {
    const Eigen::Vector2d toolbox =
        FlatGroundRange(camera.intrinsics(), r.vanishing_point_px, h, p);
    const Eigen::Vector3d ray = K_inv * p.homogeneous();
    const double down = -N.dot(ray);
    if (!std::isfinite(toolbox.x()) || !(down > 0)) {
      return Refuse(r, "ground_point_above_horizon",
                    "a ground point below the chessboard images on or above the horizon");
    }
    const Eigen::Vector3d on_ground = h / down * ray;
    r.ground_points_car_m.push_back(c.head<2>() +
                                    along * Eigen::Vector2d(on_ground.dot(F), on_ground.dot(L)));
    r.toolbox_ground_points_car_m.push_back(c.head<2>() + along * toolbox);
  }
  HomographyFitOptions exact;
  exact.refine = false;  // four points: the DLT is exact
  const std::optional<HomographyFit> ground =
      FitHomography(r.ground_points_car_m, r.ground_points_px, exact);
  const std::optional<HomographyFit> toolbox =
      FitHomography(r.toolbox_ground_points_car_m, r.ground_points_px, exact);
  if (!ground || !toolbox || std::abs(ground->H(2, 2)) < 1e-12 ||
      std::abs(toolbox->H(2, 2)) < 1e-12) {
    return Refuse(r, "ground_homography_failed", "the four ground points give no homography");
  }
  r.ground_homography = ground->H / ground->H(2, 2);
  r.toolbox_ground_homography = toolbox->H / toolbox->H(2, 2);
  r.valid = true;
  return r;
}

std::vector<double> GroundDisagreement(const Eigen::Matrix3d& H_reference,
                                       const Eigen::Matrix3d& H_other, const Eigen::Vector3d& c,
                                       int along, std::span<const double> distances_m) {
  std::vector<double> out;
  const Eigen::Matrix3d H_other_inv = H_other.inverse();
  for (double d : distances_m) {
    const Eigen::Vector2d ground(c.x() + along * d, c.y());
    const Eigen::Vector2d pixel = ApplyHomography(H_reference, ground);
    const Eigen::Vector2d back = ApplyHomography(H_other_inv, pixel);
    out.push_back((back - ground).norm() / d);  // NaN propagates from a point at infinity
  }
  return out;
}

VerticalBoardRoll RollFromVerticalBoard(const CameraModel& camera, const Board& board,
                                        const Rigid3d& T_car_board,
                                        const Eigen::Vector3d& car_x_in_camera,
                                        std::span<const DetectedFeature> features) {
  if (board.type() != BoardType::kVertical) {
    return RefuseRoll("not_a_vertical_board",
                      absl::StrCat("roll needs the vertical board, not a ", board.name()));
  }
  const Eigen::Vector3d up = T_car_board.RotationMatrix().col(1);
  if (std::atan2(up.head<2>().norm(), up.z()) > kMaxVerticalTiltRad) {
    return RefuseRoll("board_not_upright",
                      "the vertical board's columns are not vertical in the car frame");
  }
  // The corners of each column (one board x), as normalised undistorted image coordinates.
  std::map<long, std::vector<Eigen::Vector2d>> columns;
  for (const DetectedFeature& f : features) {
    Eigen::Vector3d ray;
    if (!camera.Unproject(f.uv_px, &ray) || !(ray.z() > 0)) continue;
    columns[std::lround(f.p_board.x() * 1e5)].push_back(ray.hnormalized());  // 0.01 mm bins
  }
  // V, the image of the vertical, is perpendicular to F: V = cos(phi) e1 + sin(phi) e2.
  const Eigen::Vector3d F = car_x_in_camera.normalized();
  const Eigen::Vector3d e1 = F.unitOrthogonal();
  const Eigen::Vector3d e2 = F.cross(e1);
  Eigen::Matrix2d M = Eigen::Matrix2d::Zero();
  VerticalBoardRoll r;
  for (const auto& [key, points] : columns) {
    if (static_cast<int>(points.size()) < kMinCornersPerLine) continue;
    Eigen::Vector2d mean = Eigen::Vector2d::Zero();
    for (const Eigen::Vector2d& p : points) mean += p;
    mean /= static_cast<double>(points.size());
    Eigen::Matrix2d scatter = Eigen::Matrix2d::Zero();
    for (const Eigen::Vector2d& p : points) scatter += (p - mean) * (p - mean).transpose();
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(scatter);
    const Eigen::Vector2d normal = eig.eigenvectors().col(0);
    const Eigen::Vector2d direction = eig.eigenvectors().col(1);
    double lo = 0, hi = 0;
    for (const Eigen::Vector2d& p : points) {
      lo = std::min(lo, direction.dot(p - mean));
      hi = std::max(hi, direction.dot(p - mean));
    }
    // A line's direction is known to sigma / (length sqrt(n)): weight it by the inverse.
    const double weight = (hi - lo) * std::sqrt(static_cast<double>(points.size()));
    const Eigen::Vector3d line(normal.x(), normal.y(), -normal.dot(mean));
    const Eigen::Vector2d a = weight * Eigen::Vector2d(line.dot(e1), line.dot(e2));
    M += a * a.transpose();
    ++r.lines_used;
  }
  if (r.lines_used < kMinLines) {
    return RefuseRoll("too_few_lines",
                      absl::StrCat(r.lines_used, " corner columns with ", kMinCornersPerLine,
                                   " corners, ", kMinLines, " needed"));
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(M);
  if (!(eig.eigenvalues()(1) > 0))
    return RefuseRoll("degenerate_lines", "the corner columns have no direction");
  const Eigen::Vector2d phi = eig.eigenvectors().col(0);
  Eigen::Vector3d V = phi.x() * e1 + phi.y() * e2;
  if (V.y() > 0) V = -V;  // the image of up (-y_camera) for |roll| < 90 deg
  r.roll_rad = std::atan2(-V.x(), -V.y());
  r.valid = true;
  return r;
}

}  // namespace linecal
