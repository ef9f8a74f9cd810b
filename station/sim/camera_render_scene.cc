#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <numbers>
#include <optional>
#include <vector>

#include "station/sim/camera_render_internal.h"

namespace linecal::camera_render_internal {
namespace {

// ------------------------------------------------------------------------------------------
// Labels: what a ray sees, as an id (equal ids = one region of one paint) and a reflectance.
// Surface s has ids (s + 1) << kSurfaceShift | code; 0 (kBackgroundLabel) is the background. 44
// bits leave room for the clutter codes below (16 + 40 bits of cell indices) and for 2^20
// surfaces.

constexpr int kSurfaceShift = 44;
constexpr std::uint64_t kCodeWhite = 1;
constexpr std::uint64_t kCodeBlack = 2;
constexpr std::uint64_t kCodeBack = 3;
constexpr std::uint64_t kCodePlain = 4;
// Clutter objects: kCodeClutter + 20 bits of each cell index (2^20 cells of 0.25 m wrap
// after 262 km, far beyond any wall).
constexpr std::uint64_t kCodeClutter = 16;
constexpr int kCellBits = 20;

// ------------------------------------------------------------------------------------------
// Wall clutter: a grid of kClutterCellM cells, rotated and shifted per wall; a cell holds
// one rectangle or disc with probability clutter_density.

// 0.25 m: objects of 5-23 cm, like signs, cabinets and cables on a workshop wall; at 3 m
// and 1400 px focal length they span 23-105 px.
constexpr double kClutterCellM = 0.25;
// Object size as a fraction of the cell: from clearly visible to nearly filling it.
constexpr double kClutterMinFraction = 0.2;
constexpr double kClutterMaxFraction = 0.9;
// Object greys span nearly the whole range, darker and brighter than any wall.
constexpr double kClutterMinGrey = 0.03;
constexpr double kClutterMaxGrey = 0.97;

struct ClutterObject {
  bool disc = false;
  Eigen::Vector2d centre_grid = Eigen::Vector2d::Zero();
  Eigen::Vector2d half_size = Eigen::Vector2d::Zero();  // disc: radius in both
  double grey = 0.0;

  bool Contains(const Eigen::Vector2d& p_grid) const {
    const Eigen::Vector2d d = p_grid - centre_grid;
    if (disc) return d.squaredNorm() < half_size.x() * half_size.x();
    return std::abs(d.x()) < half_size.x() && std::abs(d.y()) < half_size.y();
  }
};

std::optional<ClutterObject> ClutterInCell(const ClutterGrid& grid, std::int64_t cx,
                                           std::int64_t cy) {
  // One mix of the key and the cell indices scaled by large odd constants (2^64 / golden
  // ratio, and the fraction of sqrt(3) in 64-bit fixed point) decorrelates neighbouring
  // cells.
  const std::uint64_t h = Mix(grid.key ^ (static_cast<std::uint64_t>(cx) * 0x9e3779b97f4a7c15ULL) ^
                              (static_cast<std::uint64_t>(cy) * 0xbb67ae8584caa73bULL));
  if (Unit(h) >= grid.density) return std::nullopt;
  // The object's six parameters from 10-bit fields of one more hash: sizes and greys in
  // steps of 1/1024 of their range are as random as any.
  const std::uint64_t fields = Mix(h);
  const auto u = [&](int i) {
    return (static_cast<double>((fields >> (10 * i)) & 1023) + 0.5) / 1024;
  };
  const auto fraction = [&](int i) {
    return kClutterMinFraction + (kClutterMaxFraction - kClutterMinFraction) * u(i);
  };
  ClutterObject o;
  o.disc = u(0) < 0.5;
  const double fx = fraction(1);
  const double fy = o.disc ? fx : fraction(2);
  o.half_size = 0.5 * kClutterCellM * Eigen::Vector2d(fx, fy);
  // Anywhere in the cell that keeps the object inside it.
  const Eigen::Vector2d slack = 0.5 * Eigen::Vector2d::Constant(kClutterCellM) - o.half_size;
  o.centre_grid = kClutterCellM * Eigen::Vector2d(cx + 0.5, cy + 0.5) +
                  Eigen::Vector2d(slack.x() * (2 * u(3) - 1), slack.y() * (2 * u(4) - 1));
  o.grey = kClutterMinGrey + (kClutterMaxGrey - kClutterMinGrey) * u(5);
  return o;
}

std::array<std::int64_t, 2> ClutterCell(const Eigen::Vector2d& p_grid) {
  return {static_cast<std::int64_t>(std::floor(p_grid.x() / kClutterCellM)),
          static_cast<std::int64_t>(std::floor(p_grid.y() / kClutterCellM))};
}

std::uint64_t ClutterCode(std::int64_t cx, std::int64_t cy) {
  constexpr std::uint64_t kMask = (std::uint64_t{1} << kCellBits) - 1;
  return kCodeClutter + (((static_cast<std::uint64_t>(cx) & kMask) << kCellBits) |
                         (static_cast<std::uint64_t>(cy) & kMask));
}

}  // namespace

// ------------------------------------------------------------------------------------------
// The scene in the camera frame.

Scene::Scene(const Rigid3d& T_station_camera, const StationLayout& layout,
             const std::vector<StationSurface>& occluders, const CameraRenderOptions& options)
    : looks_{options.white_reflectance, options.black_reflectance, options.board_back_reflectance,
             options.background_reflectance} {
  const Rigid3d T_camera_station = T_station_camera.Inverse();
  const auto add = [&](SurfaceKind kind, const Rigid3d& T_station_surface,
                       const Eigen::Vector2d& size_m, double reflectance) -> SceneSurface& {
    SceneSurface s;
    s.kind = kind;
    s.label_base = static_cast<std::uint64_t>(surfaces_.size() + 1) << kSurfaceShift;
    const Rigid3d T_surface_camera = (T_camera_station * T_station_surface).Inverse();
    s.R_surface_camera = T_surface_camera.RotationMatrix();
    s.eye_surface = T_surface_camera.translation();
    s.half_size_m = 0.5 * size_m;
    s.reflectance = reflectance;
    surfaces_.push_back(s);
    return surfaces_.back();
  };
  for (const StationBoard& b : layout.boards) {
    add(SurfaceKind::kBoard, b.T_station_board, b.board.page_size_m(), 0.0).board = &b.board;
  }
  for (const StationSurface& o : occluders) {
    add(SurfaceKind::kOccluder, o.T_station_surface, o.size_m, o.reflectivity);
  }
  for (std::size_t i = 0; i < layout.surfaces.size(); ++i) {
    const StationSurface& w = layout.surfaces[i];
    SceneSurface& s = add(SurfaceKind::kWall, w.T_station_surface, w.size_m, w.reflectivity);
    if (options.clutter) {
      s.clutter = true;
      ClutterGrid& g = s.clutter_grid;
      g.density = options.clutter_density;
      g.key = Mix(options.clutter_seed, i);
      // A grid turned by 0..90 degrees, so that clutter edges take every direction.
      const double angle = 0.5 * std::numbers::pi * Unit(Mix(g.key, 1));
      g.R_grid_surface = Eigen::Rotation2Dd(angle).toRotationMatrix();
      g.offset_m = kClutterCellM * Eigen::Vector2d(Unit(Mix(g.key, 2)), Unit(Mix(g.key, 3)));
    }
  }
  add(SurfaceKind::kFloor, Rigid3d(), Eigen::Vector2d::Constant(kInf), layout.floor_reflectivity);
}

std::optional<Look> Scene::LookAt(const SceneSurface& s, const Eigen::Vector2d& p_surface) const {
  switch (s.kind) {
    case SurfaceKind::kBoard:
      return BoardLook(s, s.board->PaintAt(p_surface));
    case SurfaceKind::kWall:
      if (s.clutter) {
        const Eigen::Vector2d g =
            s.clutter_grid.R_grid_surface * p_surface + s.clutter_grid.offset_m;
        const auto [cx, cy] = ClutterCell(g);
        const std::optional<ClutterObject> o = ClutterInCell(s.clutter_grid, cx, cy);
        if (o.has_value() && o->Contains(g))
          return Look{s.label_base | ClutterCode(cx, cy), o->grey};
      }
      return Look{s.label_base | kCodePlain, s.reflectance};
    case SurfaceKind::kOccluder:
    case SurfaceKind::kFloor:
      return Look{s.label_base | kCodePlain, s.reflectance};
  }
  return std::nullopt;
}

bool Scene::UniformOver(const SceneSurface& s, const std::array<Eigen::Vector2d, 4>& p,
                        double error_px) const {
  if (s.kind == SurfaceKind::kOccluder || s.kind == SurfaceKind::kFloor ||
      (s.kind == SurfaceKind::kWall && !s.clutter)) {
    return true;
  }
  const bool clutter = s.kind == SurfaceKind::kWall;
  Eigen::Vector2d lo = Eigen::Vector2d::Constant(kInf), hi = -lo;
  for (const Eigen::Vector2d& p_surface : p) {
    const Eigen::Vector2d q =
        clutter
            ? Eigen::Vector2d(s.clutter_grid.R_grid_surface * p_surface + s.clutter_grid.offset_m)
            : p_surface;
    lo = lo.cwiseMin(q);
    hi = hi.cwiseMax(q);
  }
  const Eigen::Vector2d grow = Eigen::Vector2d::Constant(2.0 * error_px * (hi - lo).maxCoeff());
  lo -= grow;
  hi += grow;
  if (!clutter) {
    const std::optional<Paint> paint = s.board->UniformPaintIn(lo, hi);
    return paint.has_value() && (*paint == Paint::kWhite || *paint == Paint::kBlack);
  }
  // Uniform if the box lies inside one object, or meets none (it spans at most 2 x 2
  // cells, as pixels are far smaller than cells; larger boxes are left to the caller).
  const auto [x0, y0] = ClutterCell(lo);
  const auto [x1, y1] = ClutterCell(hi);
  if (x1 - x0 > 1 || y1 - y0 > 1) return false;
  const Eigen::AlignedBox2d box(lo, hi);
  for (std::int64_t cy = y0; cy <= y1; ++cy) {
    for (std::int64_t cx = x0; cx <= x1; ++cx) {
      const std::optional<ClutterObject> o = ClutterInCell(s.clutter_grid, cx, cy);
      if (!o.has_value()) continue;
      if (o->disc) {
        const double r2 = o->half_size.x() * o->half_size.x();
        if (box.squaredExteriorDistance(o->centre_grid) >= r2) continue;
        for (int i = 0; i < 4; ++i) {
          const auto corner = static_cast<Eigen::AlignedBox2d::CornerType>(i);
          if ((box.corner(corner) - o->centre_grid).squaredNorm() >= r2) return false;
        }
        return true;
      }
      const Eigen::AlignedBox2d rect(o->centre_grid - o->half_size, o->centre_grid + o->half_size);
      if (!rect.intersects(box)) continue;
      return rect.contains(box);
    }
  }
  return true;
}

std::optional<Look> Scene::BoardLook(const SceneSurface& s, Paint paint) const {
  if (paint != Paint::kWhite && paint != Paint::kBlack) return std::nullopt;
  // The camera on the printed side (board z points at the viewer) sees the print.
  if (s.eye_surface.z() <= 0.0) return Look{s.label_base | kCodeBack, looks_.back};
  if (paint == Paint::kWhite) return Look{s.label_base | kCodeWhite, looks_.white};
  return Look{s.label_base | kCodeBlack, looks_.black};
}

std::vector<std::uint32_t> AllSurfaces(const Scene& scene) {
  std::vector<std::uint32_t> all(scene.surface_count());
  for (std::size_t i = 0; i < all.size(); ++i) all[i] = static_cast<std::uint32_t>(i);
  return all;
}

}  // namespace linecal::camera_render_internal
