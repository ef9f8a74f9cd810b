#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "station/sim/camera_render_internal.h"

namespace linecal::camera_render_internal {
namespace {

// ------------------------------------------------------------------------------------------
// The pixel-corner rays: exact on a coarse grid, interpolated in between.

// Coarse grid spacing: 8 px, or 4 px for lenses too curved for 8. Bilinear interpolation of
// rays over G px is off by ~G^2 / 8 x the lens's curvature in 1/px: ~3e-3 px at 8 px for
// the reference front camera, ~1e-2 px for its fisheyes (3e-3 px at 4 px). The error only
// decides which pixels are flat; edge pixels get exact corner rays.
constexpr int kGridPx = 8;
constexpr int kFineGridPx = 4;
// A grid serves when interpolation is good enough in this fraction of its cells.
constexpr double kMinInterpolatedFraction = 0.9;
// Cells where interpolation is off by more than this get exact rays at every corner (strong
// distortion near a fisheye's rim): it bounds how far a flat pixel's footprint may be
// misplaced, i.e. the area error at an occlusion edge that grazes a pixel corner.
constexpr double kMaxInterpolationErrorPx = 0.01;
// The error measured at a cell's centre, where bilinear interpolation of a function with
// slowly varying second derivatives errs most, times this safety factor.
constexpr double kInterpolationErrorFactor = 2.0;

// Rays that leave a plane at more than asin(0.05) ~ 3 degrees never bend back to it within a
// tile: the lens mapping deviates from bilinear interpolation over a tile by < 0.2 px.
constexpr double kAwayFromPlane = 0.05;
// The footprint of a tile on a plane is known from its corner rays up to that deviation;
// growing the footprint by a quarter of its extent (4 px) covers it.
constexpr double kTileFootprintGrowth = 0.25;

static_assert(kTilePx % kGridPx == 0 && kTilePx % kFineGridPx == 0);

}  // namespace

// The pixel-corner rays.

RayGrid RayGrid::Build(const CameraModel& camera) {
  RayGrid grid(camera, kGridPx);
  return grid.InterpolatedFraction() >= kMinInterpolatedFraction ? grid
                                                                 : RayGrid(camera, kFineGridPx);
}

RayGrid::RayGrid(const CameraModel& camera, int spacing_px)
    : camera_(camera),
      spacing_px_(spacing_px),
      width_(camera.intrinsics().width),
      height_(camera.intrinsics().height),
      cols_((width_ + spacing_px - 1) / spacing_px),
      rows_((height_ + spacing_px - 1) / spacing_px) {
  rays_.resize(static_cast<std::size_t>(cols_ + 1) * (rows_ + 1));
  valid_.resize(rays_.size());
  for (int j = 0; j <= rows_; ++j) {
    for (int i = 0; i <= cols_; ++i) {
      const std::size_t k = Node(i, j);
      valid_[k] = Ray(Eigen::Vector2d(NodeX(i) - 0.5, NodeY(j) - 0.5), &rays_[k]);
    }
  }
  error_px_.assign(static_cast<std::size_t>(cols_) * rows_, kInf);
  for (int j = 0; j < rows_; ++j) {
    for (int i = 0; i < cols_; ++i) {
      if (!CellValid(i, j)) continue;
      const Eigen::Vector2d centre(0.5 * (NodeX(i) + NodeX(i + 1)) - 0.5,
                                   0.5 * (NodeY(j) + NodeY(j + 1)) - 0.5);
      const Eigen::Vector3d ray = rays_[Node(i, j)] + rays_[Node(i + 1, j)] +
                                  rays_[Node(i, j + 1)] + rays_[Node(i + 1, j + 1)];
      Eigen::Vector2d uv;
      if (camera.Project(ray, &uv)) {
        error_px_[static_cast<std::size_t>(j) * cols_ + i] =
            kInterpolationErrorFactor * (uv - centre).norm();
      }
    }
  }
}

double RayGrid::InterpolatedFraction() const {
  const auto good = std::count_if(error_px_.begin(), error_px_.end(),
                                  [](double e) { return e <= kMaxInterpolationErrorPx; });
  return static_cast<double>(good) / error_px_.size();
}

bool RayGrid::BlockRays(int i0, int j0, int i1, int j1,
                        std::array<const Eigen::Vector3d*, 4>* rays) const {
  for (int j = j0; j < j1; ++j) {
    for (int i = i0; i < i1; ++i) {
      if (!(error_px_[static_cast<std::size_t>(j) * cols_ + i] <= kMaxInterpolationErrorPx)) {
        return false;
      }
    }
  }
  *rays = {&rays_[Node(i0, j0)], &rays_[Node(i1, j0)], &rays_[Node(i0, j1)], &rays_[Node(i1, j1)]};
  return true;
}

void RayGrid::CornerRay(int x, int y, Eigen::Vector3d* ray, double* error_px, bool* valid) const {
  const int i = CellX(x), j = CellY(y);
  const double error = error_px_[static_cast<std::size_t>(j) * cols_ + i];
  if (error <= kMaxInterpolationErrorPx) {
    const double s = static_cast<double>(x - NodeX(i)) / (NodeX(i + 1) - NodeX(i));
    const double t = static_cast<double>(y - NodeY(j)) / (NodeY(j + 1) - NodeY(j));
    *ray = (1 - s) * (1 - t) * rays_[Node(i, j)] + s * (1 - t) * rays_[Node(i + 1, j)] +
           (1 - s) * t * rays_[Node(i, j + 1)] + s * t * rays_[Node(i + 1, j + 1)];
    *error_px = error;
    *valid = true;
    return;
  }
  *valid = ExactCornerRay(x, y, ray);
  *error_px = 0.0;
}

bool RayGrid::ExactCornerRay(int x, int y, Eigen::Vector3d* ray) const {
  return Ray(Eigen::Vector2d(x - 0.5, y - 0.5), ray);
}

bool RayGrid::Ray(const Eigen::Vector2d& uv, Eigen::Vector3d* ray) const {
  if (!camera_.Unproject(uv, ray)) return false;
  if (camera_.type() == CameraModelType::kPinhole) *ray /= ray->z();
  return true;
}

// The surfaces per tile.

TileCandidates::TileCandidates(const RayGrid& grid, const Scene& scene)
    : cells_per_tile_(kTilePx / grid.spacing_px()),
      cols_((grid.cols() + cells_per_tile_ - 1) / cells_per_tile_),
      rows_((grid.rows() + cells_per_tile_ - 1) / cells_per_tile_) {
  begin_.assign(static_cast<std::size_t>(cols_) * rows_ + 1, 0);
  for (int ty = 0; ty < rows_; ++ty) {
    for (int tx = 0; tx < cols_; ++tx) {
      std::array<const Eigen::Vector3d*, 4> rays;
      const bool smooth = grid.BlockRays(tx * cells_per_tile_, ty * cells_per_tile_,
                                         std::min(grid.cols(), (tx + 1) * cells_per_tile_),
                                         std::min(grid.rows(), (ty + 1) * cells_per_tile_), &rays);
      for (int s = 0; s < scene.surface_count(); ++s) {
        if (!smooth || MayShow(scene.surfaces()[s], rays)) {
          list_.push_back(static_cast<std::uint32_t>(s));
        }
      }
      begin_[static_cast<std::size_t>(ty) * cols_ + tx + 1] =
          static_cast<std::uint32_t>(list_.size());
    }
  }
}

bool TileCandidates::MayShow(const SceneSurface& s,
                             const std::array<const Eigen::Vector3d*, 4>& rays) {
  int away = 0;
  bool all_hit = true;
  Eigen::Vector2d lo = Eigen::Vector2d::Constant(kInf), hi = -lo;
  for (const Eigen::Vector3d* ray : rays) {
    const Eigen::Vector3d d = s.R_surface_camera * ray->normalized();
    // The ray heads for the plane when it moves against the side the camera is on.
    const double towards = -d.z() * (s.eye_surface.z() >= 0.0 ? 1.0 : -1.0);
    if (towards < -kAwayFromPlane) ++away;
    if (!(towards > 0.0)) {
      all_hit = false;
      continue;
    }
    const Eigen::Vector2d p = s.eye_surface.head<2>() - s.eye_surface.z() / d.z() * d.head<2>();
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  if (away == 4) return false;
  if (!all_hit) return true;
  const Eigen::Vector2d grow = kTileFootprintGrowth * (hi - lo);
  lo -= grow;
  hi += grow;
  return lo.x() <= s.half_size_m.x() && hi.x() >= -s.half_size_m.x() &&
         lo.y() <= s.half_size_m.y() && hi.y() >= -s.half_size_m.y();
}

}  // namespace linecal::camera_render_internal
