#include "station/camera/board_view.h"

#include <Eigen/SVD>
#include <algorithm>
#include <array>
#include <cmath>
#include <vector>

#include "absl/strings/str_cat.h"
#include "detectors/common/edge_lines.h"
#include "detectors/detect.h"

namespace linecal {
namespace {

// The grey of view pixels that see nothing of the raw image: between a board's black and
// white, so that the edge of the seen area makes no strong edge of its own.
constexpr std::uint8_t kUnseenGrey = 128;
// A page corner must lie at least this far in front of the view (as a share of its distance):
// a board seen edge-on has no usable perspective view.
constexpr double kMinCornerDepth = 0.05;
// A board seen within 6 degrees of edge-on (|cos| of its normal to the line of sight below
// this) shows no pattern a detector could read.
constexpr double kMinFacingCos = 0.1;
// View pixels between exactly projected nodes of the view-to-raw map (Render says why 4).
constexpr int kMapStep = 4;
// The smallest cells the detectors are made for (docs/acceptance.md, "Detectors": boards sized
// down to a 12 px square, marker boards down to a 4 px data cell).
constexpr double kMinSquarePx = 12;
constexpr double kMinMarkerCellPx = 4;

// The focal length (view pixels per unit of the view's normalised coordinates) at which a
// cell of `cell_m` at the board's centre spans `min_px` in whichever direction: the smallest
// singular value of the board plane's map to the view's normalised coordinates there. At the
// centre, as the raw image's scale is taken: a long board seen at a grazing angle (the floor
// grids) has its far cells under any such bound, and sampling for them would only make the
// view larger. 0 when no bound is asked.
double FocalForCells(const Eigen::Matrix3d& R_view_camera, const Rigid3d& T_camera_board,
                     double cell_m, double min_px) {
  if (!(cell_m > 0 && min_px > 0)) return 0;
  const Eigen::Vector3d p = R_view_camera * T_camera_board.translation();
  // d(p.xy / p.z) / d(board x, y): the projection's Jacobian times the board axes.
  Eigen::Matrix<double, 2, 3> dq;
  dq << 1 / p.z(), 0, -p.x() / (p.z() * p.z()), 0, 1 / p.z(), -p.y() / (p.z() * p.z());
  const Eigen::Matrix2d J = dq * (R_view_camera * T_camera_board.rotation()).leftCols<2>();
  const double smallest = Eigen::JacobiSVD<Eigen::Matrix2d>(J).singularValues()(1);
  return smallest > 0 ? min_px / (smallest * cell_m) : 0;
}

// Whether the board's image features are marker corners (ArUco, AprilTag, ChArUco, the
// round-hole board's markers). O(features).
bool IsMarkerBoard(const Board& board) {
  return std::any_of(board.features().begin(), board.features().end(),
                     [](const BoardFeature& f) { return f.kind == FeatureKind::kMarkerCorner; });
}

}  // namespace

absl::Status BoardViewOptions::Validate() const {
  if (!(margin >= 0 && margin <= 2))
    return absl::InvalidArgumentError(absl::StrCat("margin = ", margin, ": must be in [0, 2]"));
  if (!(scale > 0.1 && scale <= 4))
    return absl::InvalidArgumentError(absl::StrCat("scale = ", scale, ": must be in (0.1, 4]"));
  if (!(std::isfinite(smallest_cell_m) && smallest_cell_m >= 0 && std::isfinite(min_cell_px) &&
        min_cell_px >= 0)) {
    return absl::InvalidArgumentError(absl::StrCat("smallest_cell_m = ", smallest_cell_m,
                                                   ", min_cell_px = ", min_cell_px,
                                                   ": must be finite and >= 0"));
  }
  if (max_side_px < 64 || max_side_px > kMaxImageSide) {
    return absl::InvalidArgumentError(
        absl::StrCat("max_side_px = ", max_side_px, ": must be in [64, ", kMaxImageSide, "]"));
  }
  return absl::OkStatus();
}

absl::StatusOr<BoardView> BoardView::Render(const CameraModel& camera, const ImageView8& raw,
                                            const Rigid3d& T_camera_board,
                                            const Eigen::Vector2d& page_size_m,
                                            const BoardViewOptions& options) {
  if (absl::Status s = options.Validate(); !s.ok()) return s;
  if (raw.Validate() != ImageViewError::kOk)
    return absl::InvalidArgumentError("raw image: invalid view");
  const Eigen::Vector3d p_centre = T_camera_board.translation();
  Eigen::Vector2d uv_centre;
  ProjectionPointJacobian J;
  if (!camera.Project(p_centre, &uv_centre, &J)) {
    return absl::InvalidArgumentError(
        "the expected board centre is outside the camera's valid region");
  }
  BoardView view;
  const Eigen::Vector3d z = p_centre.normalized();
  if (std::abs(z.dot(T_camera_board.rotation() * Eigen::Vector3d::UnitZ())) < kMinFacingCos) {
    return absl::InvalidArgumentError("the board is expected edge-on: no perspective view");
  }
  Eigen::Vector3d x = Eigen::Vector3d::UnitX() - z.x() * z;
  if (x.norm() < 1e-6)
    x = Eigen::Vector3d::UnitY() - z.y() * z;  // looking along the camera's x axis
  x.normalize();
  view.R_camera_view_.col(0) = x;
  view.R_camera_view_.col(1) = z.cross(x);
  view.R_camera_view_.col(2) = z;

  // Raw pixels per radian of view direction at the centre: the Jacobian times the distance,
  // on the view's x and y; its larger singular value is the finest scale.
  const Eigen::Matrix2d local = J * view.R_camera_view_.leftCols<2>() * p_centre.norm();
  double f = std::max(options.scale * Eigen::JacobiSVD<Eigen::Matrix2d>(local).singularValues()(0),
                      FocalForCells(view.R_camera_view_.transpose(), T_camera_board,
                                    options.smallest_cell_m, options.min_cell_px));

  const double grow = options.margin * page_size_m.maxCoeff();
  const double hx = page_size_m.x() / 2 + grow, hy = page_size_m.y() / 2 + grow;
  std::array<Eigen::Vector3d, 4> corners_view;
  int k = 0;
  for (double sx : {-1.0, 1.0}) {
    for (double sy : {-1.0, 1.0}) {
      const Eigen::Vector3d p_view =
          view.R_camera_view_.transpose() * (T_camera_board * Eigen::Vector3d(sx * hx, sy * hy, 0));
      if (p_view.z() < kMinCornerDepth * p_view.norm()) {
        return absl::InvalidArgumentError(
            "the board is expected edge-on or behind the view: no perspective view");
      }
      corners_view[k++] = p_view;
    }
  }
  Eigen::Vector2d lo = Eigen::Vector2d::Constant(1e300), hi = -lo;
  for (const Eigen::Vector3d& p : corners_view) {
    const Eigen::Vector2d q = p.head<2>() / p.z();
    lo = lo.cwiseMin(q);
    hi = hi.cwiseMax(q);
  }
  f = std::min(f, options.max_side_px / (hi - lo).maxCoeff());
  view.f_px_ = f;
  view.c_px_ = -lo * f;
  const int width = std::max(1, static_cast<int>(std::ceil((hi.x() - lo.x()) * f)) + 1);
  const int height = std::max(1, static_cast<int>(std::ceil((hi.y() - lo.y()) * f)) + 1);
  view.image_ = Image8(width, height, kUnseenGrey);
  // The raw position of every kMapStep-th view pixel exactly (one projection each), bilinear
  // in between, at a sixteenth of the projections. The map is smooth: on the reference
  // station's surround views the interpolation stays within 0.0035 px of the exact map (0.014
  // px with a step of 8, the error growing with the step squared), under the checkers'
  // 0.005 px corner error. Cells with a corner outside the camera's valid region are
  // projected pixel by pixel.
  const int nodes_u = (width - 1) / kMapStep + 2, nodes_v = (height - 1) / kMapStep + 2;
  std::vector<std::optional<Eigen::Vector2d>> nodes(static_cast<std::size_t>(nodes_u) * nodes_v);
  for (int j = 0; j < nodes_v; ++j) {
    for (int i = 0; i < nodes_u; ++i) {
      nodes[static_cast<std::size_t>(j) * nodes_u + i] =
          view.ToRaw(camera, Eigen::Vector2d(i * kMapStep, j * kMapStep));
    }
  }
  for (int v = 0; v < height; ++v) {
    const int j = v / kMapStep;
    const double fv = static_cast<double>(v - j * kMapStep) / kMapStep;
    for (int u = 0; u < width; ++u) {
      const int i = u / kMapStep;
      const double fu = static_cast<double>(u - i * kMapStep) / kMapStep;
      const std::optional<Eigen::Vector2d>* n = &nodes[static_cast<std::size_t>(j) * nodes_u + i];
      std::optional<Eigen::Vector2d> uv;
      if (n[0] && n[1] && n[nodes_u] && n[nodes_u + 1]) {
        uv = (1 - fv) * ((1 - fu) * *n[0] + fu * *n[1]) +
             fv * ((1 - fu) * *n[nodes_u] + fu * *n[nodes_u + 1]);
      } else {
        uv = view.ToRaw(camera, Eigen::Vector2d(u, v));
      }
      if (uv && InsideForBilinearGrey(raw, *uv)) {
        view.image_.at(u, v) =
            static_cast<std::uint8_t>(std::lround(BilinearGrey(raw, uv->x(), uv->y())));
      }
    }
  }
  return view;
}

std::optional<Eigen::Vector2d> BoardView::ToRaw(const CameraModel& camera,
                                                const Eigen::Vector2d& uv_view_px) const {
  const Eigen::Vector3d ray_view((uv_view_px.x() - c_px_.x()) / f_px_,
                                 (uv_view_px.y() - c_px_.y()) / f_px_, 1.0);
  Eigen::Vector2d uv;
  if (!camera.Project(R_camera_view_ * ray_view, &uv)) return std::nullopt;
  return uv;
}

namespace {

// `board` detected in `view`, its features mapped back to raw pixels; nullopt when the board
// has no image detector or a feature maps outside the camera's valid region.
std::optional<Detection> DetectInView(const CameraModel& camera, const BoardView& view,
                                      const Board& board) {
  std::optional<Detection> d = DetectBoard(view.image().view(), board);
  if (!d) return std::nullopt;
  for (DetectedFeature& f : d->features) {
    const std::optional<Eigen::Vector2d> uv = view.ToRaw(camera, f.uv_px);
    if (!uv) return std::nullopt;
    f.uv_px = *uv;
  }
  return d;
}

}  // namespace

std::optional<Detection> DetectInBoardView(const CameraModel& camera, const ImageView8& raw,
                                           const Rigid3d& T_camera_board, const Board& board,
                                           const BoardViewOptions& options) {
  absl::StatusOr<BoardView> view =
      BoardView::Render(camera, raw, T_camera_board, board.page_size_m(), options);
  if (!view.ok()) return std::nullopt;
  std::optional<Detection> d = DetectInView(camera, *view, board);
  if (!d || d->found) return d;
  // Not found: again in a view whose smallest cell reaches the detectors' smallest size, when
  // that view is finer. Only then: a board found at the raw scale keeps its corners, and with
  // them its residuals, from which the solvers estimate the feature noise (finer views of the
  // floor grids gave the same errors with a smaller sigma in `linecal eval station`).
  BoardViewOptions sized = options;
  sized.smallest_cell_m = SmallestCellM(board);
  sized.min_cell_px = IsMarkerBoard(board) ? kMinMarkerCellPx : kMinSquarePx;
  absl::StatusOr<BoardView> finer =
      BoardView::Render(camera, raw, T_camera_board, board.page_size_m(), sized);
  if (!finer.ok() || finer->image().width <= view->image().width) return d;
  std::optional<Detection> again = DetectInView(camera, *finer, board);
  return again && again->found ? again : d;
}

}  // namespace linecal
