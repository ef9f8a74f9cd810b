#include "station/sim/camera_render.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <limits>
#include <numbers>
#include <optional>
#include <random>
#include <thread>
#include <utility>

#include "absl/strings/str_cat.h"
#include "absl/strings/string_view.h"

namespace linecal {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

// ------------------------------------------------------------------------------------------
// Option limits (the reasons are in the header's field comments).

constexpr int kMinEdgeProbes = 2;
constexpr int kMaxEdgeProbes = 64;
constexpr double kMinEdgeTolerancePx = 1e-7;
constexpr double kMaxEdgeTolerancePx = 0.05;
constexpr int kMaxSubdivisionDepth = 10;
constexpr double kMaxIllumination = 100.0;
constexpr double kMaxGradientRatio = 4.0;
constexpr double kMaxBlurSigmaPx = 10.0;
constexpr double kMinGamma = 0.2;
constexpr double kMaxGamma = 5.0;
constexpr double kMaxNoiseSigma = 64.0;
constexpr int kMinJpegQuality = 80;
constexpr int kMaxJpegQuality = 100;
constexpr int kMaxOccluders = 64;
constexpr double kMaxOccluderSizePx = 4096.0;
constexpr double kMaxFeatureMarginPx = 1000.0;
constexpr int kMaxThreads = 16;

absl::Status OutOfRange(absl::string_view field, double value, absl::string_view range) {
  return absl::InvalidArgumentError(absl::StrCat(field, " = ", value, ": must be in ", range));
}

// OK when lo <= value <= hi (NaN fails).
absl::Status CheckClosed(absl::string_view field, double value, double lo, double hi) {
  if (value >= lo && value <= hi) return absl::OkStatus();
  return OutOfRange(field, value, absl::StrCat("[", lo, ", ", hi, "]"));
}

// ------------------------------------------------------------------------------------------
// Hashing: seeds, per-row noise streams and the procedural clutter.

// The finaliser of SplitMix64: a bijective 64-bit mixer whose outputs pass BigCrush.
std::uint64_t Mix(std::uint64_t x) {
  x += 0x9e3779b97f4a7c15ULL;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
  return x ^ (x >> 31);
}

std::uint64_t Mix(std::uint64_t a, std::uint64_t b) { return Mix(a ^ Mix(b)); }

// Uniform in [0, 1) from the top 53 bits of a hash.
double Unit(std::uint64_t h) { return static_cast<double>(h >> 11) * 0x1.0p-53; }

// Independent streams drawn from the frame seed.
constexpr std::uint64_t kNoiseStream = 1;
constexpr std::uint64_t kOccluderStream = 2;

// ------------------------------------------------------------------------------------------
// Labels: what a ray sees, as an id (equal ids = one region of one paint) and a reflectance.
// Surface s has ids (s + 1) << kSurfaceShift | code; 0 is the background. 44 bits leave room
// for the clutter codes below (16 + 40 bits of cell indices) and for 2^20 surfaces.

constexpr int kSurfaceShift = 44;
constexpr std::uint64_t kCodeWhite = 1;
constexpr std::uint64_t kCodeBlack = 2;
constexpr std::uint64_t kCodeBack = 3;
constexpr std::uint64_t kCodePlain = 4;
// Clutter objects: kCodeClutter + 20 bits of each cell index (2^20 cells of 0.25 m wrap
// after 262 km, far beyond any wall).
constexpr std::uint64_t kCodeClutter = 16;
constexpr int kCellBits = 20;
constexpr std::uint64_t kBackgroundLabel = 0;

struct Look {
  std::uint64_t label = kBackgroundLabel;
  double reflectance = 0.0;
};

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

struct ClutterGrid {
  double density = 0.0;
  std::uint64_t key = 0;
  Eigen::Matrix2d R_grid_surface = Eigen::Matrix2d::Identity();
  Eigen::Vector2d offset_m = Eigen::Vector2d::Zero();
};

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
  const auto u = [&](int i) { return (static_cast<double>((fields >> (10 * i)) & 1023) + 0.5) / 1024; };
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

// ------------------------------------------------------------------------------------------
// The scene in the camera frame.

enum class SurfaceKind : std::uint8_t { kBoard, kOccluder, kWall, kFloor };

struct SceneSurface {
  SurfaceKind kind = SurfaceKind::kWall;
  std::uint64_t label_base = 0;
  // Camera-frame directions to surface-frame directions, and the camera centre in the
  // surface frame: a ray t * d_camera meets the plane z_surface = 0 where
  // eye.z + t (R d).z = 0.
  Eigen::Matrix3d R_surface_camera = Eigen::Matrix3d::Identity();
  Eigen::Vector3d eye_surface = Eigen::Vector3d::Zero();
  Eigen::Vector2d half_size_m = Eigen::Vector2d::Zero();  // the floor: infinite
  double reflectance = 0.0;                               // walls, occluders, the floor
  const Board* board = nullptr;                           // boards
  bool clutter = false;                                   // walls with clutter
  ClutterGrid clutter_grid;
};

struct SceneLooks {
  double white = 0.0;
  double black = 0.0;
  double back = 0.0;
  double background = 0.0;
};

struct Hit {
  Look look;
  int surface = -1;  // -1: nothing
  double t = kInf;   // ray parameter: the hit is t * d
  Eigen::Vector2d p_surface = Eigen::Vector2d::Zero();
};

class Scene {
 public:
  Scene(const Rigid3d& T_station_camera, const StationLayout& layout,
        const std::vector<StationSurface>& occluders, const CameraRenderOptions& options)
      : looks_{options.white_reflectance, options.black_reflectance,
               options.board_back_reflectance, options.background_reflectance} {
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
    add(SurfaceKind::kFloor, Rigid3d(), Eigen::Vector2d::Constant(kInf),
        layout.floor_reflectivity);
  }

  const std::vector<SceneSurface>& surfaces() const { return surfaces_; }
  int surface_count() const { return static_cast<int>(surfaces_.size()); }

  // Where the ray t * d_camera (0 < t < max_t) meets the plane of surface s inside its
  // extent.
  static bool Intersect(const SceneSurface& s, const Eigen::Vector3d& d_camera, double max_t,
                        double* t, Eigen::Vector2d* p_surface) {
    const double tt = -s.eye_surface.z() / s.R_surface_camera.row(2).dot(d_camera);
    // Also refuses rays parallel to the plane (inf or NaN).
    if (!(tt > 0.0 && tt < max_t)) return false;
    const Eigen::Vector2d p =
        s.eye_surface.head<2>() + tt * (s.R_surface_camera.topRows<2>() * d_camera);
    if (!(std::abs(p.x()) <= s.half_size_m.x() && std::abs(p.y()) <= s.half_size_m.y())) {
      return false;
    }
    *t = tt;
    *p_surface = p;
    return true;
  }

  // What surface s shows at p_surface (a point inside its extent); nullopt where it lets
  // the ray through (holes, off the page).
  std::optional<Look> LookAt(const SceneSurface& s, const Eigen::Vector2d& p_surface) const {
    switch (s.kind) {
      case SurfaceKind::kBoard:
        return BoardLook(s, s.board->PaintAt(p_surface));
      case SurfaceKind::kWall:
        if (s.clutter) {
          const Eigen::Vector2d g = s.clutter_grid.R_grid_surface * p_surface + s.clutter_grid.offset_m;
          const auto [cx, cy] = ClutterCell(g);
          const std::optional<ClutterObject> o = ClutterInCell(s.clutter_grid, cx, cy);
          if (o.has_value() && o->Contains(g)) return Look{s.label_base | ClutterCode(cx, cy), o->grey};
        }
        return Look{s.label_base | kCodePlain, s.reflectance};
      case SurfaceKind::kOccluder:
      case SurfaceKind::kFloor:
        return Look{s.label_base | kCodePlain, s.reflectance};
    }
    return std::nullopt;
  }

  // True if surface s shows one look over the whole footprint of a pixel whose corners hit
  // it at p (conservative: false when unsure). The footprint lies in the convex hull of
  // the corners' hits; corner rays off by up to error_px pixels move them by about that
  // fraction of the footprint's extent, so the corners' bounding box is grown by twice
  // that.
  bool UniformOver(const SceneSurface& s, const std::array<Eigen::Vector2d, 4>& p,
                   double error_px) const {
    if (s.kind == SurfaceKind::kOccluder || s.kind == SurfaceKind::kFloor ||
        (s.kind == SurfaceKind::kWall && !s.clutter)) {
      return true;
    }
    const bool clutter = s.kind == SurfaceKind::kWall;
    Eigen::Vector2d lo = Eigen::Vector2d::Constant(kInf), hi = -lo;
    for (const Eigen::Vector2d& p_surface : p) {
      const Eigen::Vector2d q =
          clutter ? Eigen::Vector2d(s.clutter_grid.R_grid_surface * p_surface + s.clutter_grid.offset_m)
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

  // The nearest opaque hit of the ray t * d_camera among the candidate surfaces, skipping
  // surface `exclude` and hits at t >= max_t; the background look if there is none.
  Hit Trace(const Eigen::Vector3d& d_camera, const std::uint32_t* candidates, int n,
            int exclude = -1, double max_t = kInf) const {
    Hit best;
    best.t = max_t;
    best.look = Look{kBackgroundLabel, looks_.background};
    for (int k = 0; k < n; ++k) {
      const int i = static_cast<int>(candidates[k]);
      if (i == exclude) continue;
      const SceneSurface& s = surfaces_[i];
      double t;
      Eigen::Vector2d p;
      if (!Intersect(s, d_camera, best.t, &t, &p)) continue;
      const std::optional<Look> look = LookAt(s, p);
      if (!look.has_value()) continue;
      best.look = *look;
      best.surface = i;
      best.t = t;
      best.p_surface = p;
    }
    return best;
  }

 private:
  std::optional<Look> BoardLook(const SceneSurface& s, Paint paint) const {
    if (paint != Paint::kWhite && paint != Paint::kBlack) return std::nullopt;
    // The camera on the printed side (board z points at the viewer) sees the print.
    if (s.eye_surface.z() <= 0.0) return Look{s.label_base | kCodeBack, looks_.back};
    if (paint == Paint::kWhite) return Look{s.label_base | kCodeWhite, looks_.white};
    return Look{s.label_base | kCodeBlack, looks_.black};
  }

  SceneLooks looks_;
  std::vector<SceneSurface> surfaces_;
};

std::vector<std::uint32_t> AllSurfaces(const Scene& scene) {
  std::vector<std::uint32_t> all(scene.surface_count());
  for (std::size_t i = 0; i < all.size(); ++i) all[i] = static_cast<std::uint32_t>(i);
  return all;
}

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

class RayGrid {
 public:
  // kGridPx if that serves, else kFineGridPx.
  static RayGrid Build(const CameraModel& camera) {
    RayGrid grid(camera, kGridPx);
    return grid.InterpolatedFraction() >= kMinInterpolatedFraction ? grid
                                                                   : RayGrid(camera, kFineGridPx);
  }

  RayGrid(const CameraModel& camera, int spacing_px)
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

  int spacing_px() const { return spacing_px_; }
  int cols() const { return cols_; }
  int rows() const { return rows_; }
  // The cell holding pixel (x, y), or pixel corner (x - 0.5, y - 0.5); corners on the right
  // and bottom edges of the image belong to the last cells.
  int CellX(int x) const { return std::min(x / spacing_px_, cols_ - 1); }
  int CellY(int y) const { return std::min(y / spacing_px_, rows_ - 1); }

  double InterpolatedFraction() const {
    const auto good = std::count_if(error_px_.begin(), error_px_.end(),
                                    [](double e) { return e <= kMaxInterpolationErrorPx; });
    return static_cast<double>(good) / error_px_.size();
  }

  // The node rays at the corners of the block of cells [i0, i1) x [j0, j1): top-left,
  // top-right, bottom-left, bottom-right; false unless interpolation serves in every cell
  // of the block (so its rays are valid and the lens mapping is smooth over it).
  bool BlockRays(int i0, int j0, int i1, int j1,
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

  // The ray of pixel corner (x - 0.5, y - 0.5), 0 <= x <= width, 0 <= y <= height (not
  // unit length), and an upper bound of its error in pixels (0 when exact). Rays of
  // invalid corners: *valid = false.
  void CornerRay(int x, int y, Eigen::Vector3d* ray, double* error_px, bool* valid) const {
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

  bool ExactCornerRay(int x, int y, Eigen::Vector3d* ray) const {
    return Ray(Eigen::Vector2d(x - 0.5, y - 0.5), ray);
  }

 private:
  // The ray of image point uv: for a pinhole scaled to z = 1, where the undistorted image
  // is linear in the ray, so that blends of rays are exact rays of blended pixels; for a
  // fisheye (rays may point backwards) of unit length.
  bool Ray(const Eigen::Vector2d& uv, Eigen::Vector3d* ray) const {
    if (!camera_.Unproject(uv, ray)) return false;
    if (camera_.type() == CameraModelType::kPinhole) *ray /= ray->z();
    return true;
  }

  int NodeX(int i) const { return std::min(i * spacing_px_, width_); }
  int NodeY(int j) const { return std::min(j * spacing_px_, height_); }
  std::size_t Node(int i, int j) const { return static_cast<std::size_t>(j) * (cols_ + 1) + i; }
  bool CellValid(int i, int j) const {
    return valid_[Node(i, j)] && valid_[Node(i + 1, j)] && valid_[Node(i, j + 1)] &&
           valid_[Node(i + 1, j + 1)];
  }

  const CameraModel& camera_;
  const int spacing_px_;
  const int width_;
  const int height_;
  const int cols_;
  const int rows_;
  std::vector<Eigen::Vector3d> rays_;
  std::vector<char> valid_;
  std::vector<double> error_px_;  // per cell; inf where interpolation is not possible
};

// Per tile of kTilePx x kTilePx pixels, the surfaces that may show in it.

// 16 px: testing a tile costs four ray-plane intersections per surface, 1/64 of the
// per-corner work it saves, and tiles stay small enough to exclude most surfaces.
constexpr int kTilePx = 16;
static_assert(kTilePx % kGridPx == 0 && kTilePx % kFineGridPx == 0);
// Rays that leave a plane at more than asin(0.05) ~ 3 degrees never bend back to it within a
// tile: the lens mapping deviates from bilinear interpolation over a tile by < 0.2 px.
constexpr double kAwayFromPlane = 0.05;
// The footprint of a tile on a plane is known from its corner rays up to that deviation;
// growing the footprint by a quarter of its extent (4 px) covers it.
constexpr double kTileFootprintGrowth = 0.25;

class TileCandidates {
 public:
  TileCandidates(const RayGrid& grid, const Scene& scene)
      : cells_per_tile_(kTilePx / grid.spacing_px()),
        cols_((grid.cols() + cells_per_tile_ - 1) / cells_per_tile_),
        rows_((grid.rows() + cells_per_tile_ - 1) / cells_per_tile_) {
    begin_.assign(static_cast<std::size_t>(cols_) * rows_ + 1, 0);
    for (int ty = 0; ty < rows_; ++ty) {
      for (int tx = 0; tx < cols_; ++tx) {
        std::array<const Eigen::Vector3d*, 4> rays;
        const bool smooth = grid.BlockRays(
            tx * cells_per_tile_, ty * cells_per_tile_,
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

  // The candidates of the tile holding pixel (x, y) or pixel corner (x - 0.5, y - 0.5);
  // corners on the image's right and bottom edges belong to the last tiles.
  std::pair<const std::uint32_t*, int> At(int x, int y) const {
    const int tx = std::min(x / kTilePx, cols_ - 1), ty = std::min(y / kTilePx, rows_ - 1);
    const std::size_t t = static_cast<std::size_t>(ty) * cols_ + tx;
    return {list_.data() + begin_[t], static_cast<int>(begin_[t + 1] - begin_[t])};
  }

 private:
  static bool MayShow(const SceneSurface& s, const std::array<const Eigen::Vector3d*, 4>& rays) {
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

  const int cells_per_tile_;
  const int cols_;
  const int rows_;
  std::vector<std::uint32_t> begin_;
  std::vector<std::uint32_t> list_;
};

// ------------------------------------------------------------------------------------------
// Integrating one pixel.
//
// Pixel-local coordinates (s, t) in [0, 1]^2 run along u and v; the ray at (s, t) is the
// bilinear blend of the four corner rays. A cell (the pixel or a quarter of it, ...) is
// probed on its boundary; no change of label around it (and its centre agreeing) means
// one look; exactly two changes mean one boundary curve between two looks, which is
// located by bisection at its two ends and its middle and integrated as a parabolic arc
// (exact for straight edges; circles of radius R px are off by ~L^4/R^3 of a pixel), after
// two more probes confirm the arc. Anything else splits the cell into quarters.

// A pixel corner: its ray (camera frame, not unit length) and what it hits.
struct CornerSample {
  Eigen::Vector3d ray = Eigen::Vector3d::Zero();
  double error_px = 0.0;  // bound on the ray's error in pixels; 0 = exact
  bool valid = false;
  Hit hit;
};

// True if all four corners of a pixel hit one surface and every other candidate's plane
// lies behind it (or is never met) along all four corner rays: depths along blended rays
// are harmonic blends of the corners' depths, so that order holds inside the pixel too.
bool InFrontOverPixel(const Scene& scene, const std::array<CornerSample*, 4>& c,
                      const std::uint32_t* candidates, int n) {
  const int front = c[0]->hit.surface;
  if (front < 0) return false;
  for (int k = 1; k < 4; ++k) {
    if (c[k]->hit.surface != front) return false;
  }
  for (int i = 0; i < n; ++i) {
    const int other = static_cast<int>(candidates[i]);
    if (other == front) continue;
    const SceneSurface& o = scene.surfaces()[other];
    bool behind = true, never = true;
    for (int k = 0; k < 4; ++k) {
      const double t = -o.eye_surface.z() / o.R_surface_camera.row(2).dot(c[k]->ray);
      behind = behind && t > c[k]->hit.t;
      never = never && t < 0.0;
    }
    if (!behind && !never) return false;
  }
  return true;
}

class PixelIntegrator {
 public:
  PixelIntegrator(const Scene& scene, const CameraRenderOptions& options)
      : scene_(scene),
        probes_(options.edge_probes_per_side),
        tolerance_(options.edge_tolerance_px),
        max_depth_(options.max_subdivision_depth) {}

  // Mean reflectance over the pixel whose corners (exact rays) are c[0] (top-left), c[1]
  // (top-right), c[2] (bottom-left), c[3] (bottom-right).
  double Integrate(const std::array<CornerSample*, 4>& c, const std::uint32_t* candidates, int n) {
    for (int k = 0; k < 4; ++k) rays_[k] = &c[k]->ray;
    candidates_ = candidates;
    n_candidates_ = n;
    front_ = FrontSurface(c);
    if (front_ != nullptr) {
      for (int k = 0; k < 4; ++k) {
        q_[k] = c[k]->hit.p_surface;
        inverse_t_[k] = 1.0 / c[k]->hit.t;
      }
    }
    // Loop order: top-left, top-right, bottom-right, bottom-left.
    return Cell(Eigen::Vector2d::Zero(), 1.0, 0,
                {c[0]->hit.look, c[1]->hit.look, c[3]->hit.look, c[2]->hit.look});
  }

 private:
  static constexpr int kMaxLoop = 4 * kMaxEdgeProbes;

  // The surface the pixel's corners all hit, if it is in front over the whole pixel.
  const SceneSurface* FrontSurface(const std::array<CornerSample*, 4>& c) const {
    if (!InFrontOverPixel(scene_, c, candidates_, n_candidates_)) return nullptr;
    return &scene_.surfaces()[c[0]->hit.surface];
  }

  Look Eval(const Eigen::Vector2d& st) const {
    const double s = st.x(), t = st.y();
    const std::array<double, 4> w = {(1 - s) * (1 - t), s * (1 - t), (1 - s) * t, s * t};
    if (front_ != nullptr) {
      // Where the blended ray meets the front surface: the corners' hits blended with
      // weights w / depth (perspective-correct), no ray-plane intersection needed.
      Eigen::Vector2d p = Eigen::Vector2d::Zero();
      double total = 0.0;
      for (int k = 0; k < 4; ++k) {
        p += w[k] * inverse_t_[k] * q_[k];
        total += w[k] * inverse_t_[k];
      }
      p /= total;
      if (std::abs(p.x()) <= front_->half_size_m.x() && std::abs(p.y()) <= front_->half_size_m.y()) {
        if (const std::optional<Look> look = scene_.LookAt(*front_, p)) return *look;
      }
    }
    const Eigen::Vector3d d = w[0] * *rays_[0] + w[1] * *rays_[1] + w[2] * *rays_[2] + w[3] * *rays_[3];
    return scene_.Trace(d, candidates_, n_candidates_).look;
  }

  // Position of loop sample k of the cell at `origin` with side `size`, `per_side` samples
  // per side, starting at the top-left corner and running through top-right, bottom-right
  // and bottom-left: positively oriented in (s, t).
  static Eigen::Vector2d LoopPoint(const Eigen::Vector2d& origin, double size, int per_side,
                                   int k) {
    const int side = k / per_side;
    const double f = size * (k % per_side) / per_side;
    switch (side) {
      case 0:
        return origin + Eigen::Vector2d(f, 0);
      case 1:
        return origin + Eigen::Vector2d(size, f);
      case 2:
        return origin + Eigen::Vector2d(size - f, size);
      default:
        return origin + Eigen::Vector2d(0, size - f);
    }
  }

  // Shrinks [a, b] (labels la != lb) around the label change; false if a third label shows.
  bool Bisect(Eigen::Vector2d a, std::uint64_t la, Eigen::Vector2d b, std::uint64_t lb,
              Eigen::Vector2d* crossing) const {
    while ((b - a).norm() > tolerance_) {
      const Eigen::Vector2d m = 0.5 * (a + b);
      const std::uint64_t lm = Eval(m).label;
      if (lm == la) {
        a = m;
      } else if (lm == lb) {
        b = m;
      } else {
        return false;
      }
    }
    *crossing = 0.5 * (a + b);
    return true;
  }

  // Integral of reflectance over the cell (area in pixels^2 times reflectance). `corners`:
  // the looks at the loop's four corners.
  double Cell(const Eigen::Vector2d& origin, double size, int depth,
              const std::array<Look, 4>& corners) {
    const int per_side = std::max(kMinEdgeProbes, probes_ >> depth);
    const int n = 4 * per_side;
    std::array<Look, kMaxLoop> loop;
    for (int k = 0; k < n; ++k) {
      loop[k] = k % per_side == 0 ? corners[k / per_side]
                                  : Eval(LoopPoint(origin, size, per_side, k));
    }
    std::array<int, 3> changes;
    int n_changes = 0;
    for (int k = 0; k < n && n_changes < 3; ++k) {
      if (loop[k].label != loop[(k + 1) % n].label) changes[n_changes++] = k;
    }
    const double area = size * size;
    const Eigen::Vector2d centre = origin + Eigen::Vector2d::Constant(0.5 * size);
    if (n_changes == 0) {
      const Look c = Eval(centre);
      if (c.label == loop[0].label) return area * c.reflectance;
    } else if (n_changes == 2) {
      double value;
      if (Arc(origin, size, per_side, loop, changes[0], changes[1], &value)) return value;
    }
    if (depth == max_depth_) {
      // Smallest cell: the mean of its probes and its centre.
      double sum = Eval(centre).reflectance;
      for (int k = 0; k < n; ++k) sum += loop[k].reflectance;
      return area * sum / (n + 1);
    }
    const double half = 0.5 * size;
    const Look top = Eval(origin + Eigen::Vector2d(half, 0));
    const Look right = Eval(origin + Eigen::Vector2d(size, half));
    const Look bottom = Eval(origin + Eigen::Vector2d(half, size));
    const Look left = Eval(origin + Eigen::Vector2d(0, half));
    const Look mid = Eval(centre);
    return Cell(origin, half, depth + 1, {corners[0], top, mid, left}) +
           Cell(origin + Eigen::Vector2d(half, 0), half, depth + 1, {top, corners[1], right, mid}) +
           Cell(origin + Eigen::Vector2d(half, half), half, depth + 1,
                {mid, right, corners[2], bottom}) +
           Cell(origin + Eigen::Vector2d(0, half), half, depth + 1, {left, mid, bottom, corners[3]});
  }

  // The cell split by one arc: the loop changes from look A to B after sample k1 and back
  // after sample k2. False when the arc is not smooth enough to integrate (the caller then
  // splits the cell).
  bool Arc(const Eigen::Vector2d& origin, double size, int per_side,
           const std::array<Look, kMaxLoop>& loop, int k1, int k2, double* value) const {
    const int n = 4 * per_side;
    const Look& a = loop[(k2 + 1) % n];  // the arc k2+1 .. k1
    const Look& b = loop[(k1 + 1) % n];  // the arc k1+1 .. k2
    const auto point = [&](int k) { return LoopPoint(origin, size, per_side, k % n); };
    Eigen::Vector2d p, q;
    if (!Bisect(point(k1), a.label, point(k1 + 1), b.label, &p) ||
        !Bisect(point(k2), b.label, point(k2 + 1), a.label, &q)) {
      return false;
    }
    // The part of the cell on A's side of the chord p-q: q, the cell corners on A's arc,
    // p. It runs in the loop's positive sense, so A lies left of p -> q.
    std::array<Eigen::Vector2d, 6> polygon;
    int m = 0;
    polygon[m++] = q;
    for (int k = k2 + 1; k <= k2 + n; ++k) {
      const int kk = k % n;
      if (kk == (k1 + 1) % n) break;
      if (kk % per_side == 0) polygon[m++] = point(kk);
    }
    polygon[m++] = p;
    double twice_area_a = 0.0;
    for (int i = 0; i < m; ++i) {
      const Eigen::Vector2d& u = polygon[i];
      const Eigen::Vector2d& w = polygon[(i + 1) % m];
      twice_area_a += u.x() * w.y() - u.y() * w.x();
    }
    const Eigen::Vector2d chord = q - p;
    const double length = chord.norm();
    if (!(length > 0.0)) return false;
    const Eigen::Vector2d normal = Eigen::Vector2d(-chord.y(), chord.x()) / length;  // to A
    // The arc's offset from the chord at its middle, searched a quarter chord either side:
    // a bulge beyond that is a corner, not an arc.
    const Eigen::Vector2d middle = 0.5 * (p + q);
    const double reach = 0.25 * length + tolerance_;
    const Eigen::Vector2d on_a = middle + reach * normal, on_b = middle - reach * normal;
    if (Eval(on_a).label != a.label || Eval(on_b).label != b.label) return false;
    Eigen::Vector2d x;
    if (!Bisect(on_b, b.label, on_a, a.label, &x)) return false;
    const double offset = (x - middle).dot(normal);  // > 0: B bulges into A's side
    // Confirm a parabola through p, x and q at a quarter and three quarters of the chord
    // (offset 3/4 of the middle's), to twice the bisection tolerance.
    const double slack = 2.0 * tolerance_;
    for (const double f : {0.25, 0.75}) {
      const Eigen::Vector2d c = p + f * chord + 0.75 * offset * normal;
      if (Eval(c + slack * normal).label != a.label || Eval(c - slack * normal).label != b.label) {
        return false;
      }
    }
    // The segment between a parabolic arc and its chord has 2/3 of the area of the
    // enclosing parallelogram.
    const double area = size * size;
    const double area_a = std::clamp(0.5 * twice_area_a - 2.0 / 3.0 * length * offset, 0.0, area);
    *value = area_a * a.reflectance + (area - area_a) * b.reflectance;
    return true;
  }

  const Scene& scene_;
  const int probes_;
  const double tolerance_;
  const int max_depth_;
  std::array<const Eigen::Vector3d*, 4> rays_{};
  const std::uint32_t* candidates_ = nullptr;
  int n_candidates_ = 0;
  const SceneSurface* front_ = nullptr;
  std::array<Eigen::Vector2d, 4> q_;     // the corners' hits on *front_
  std::array<double, 4> inverse_t_{};  // 1 / their depths along the corner rays
};

// ------------------------------------------------------------------------------------------
// Rendering the linear image.

// Rows of pixels handed out at a time: work is spread evenly whatever the scene, and each
// band recomputes one corner row (1/16 extra).
constexpr int kBandRows = 16;

class LinearRenderer {
 public:
  LinearRenderer(const CameraModel& camera, const Scene& scene, const CameraRenderOptions& options)
      : camera_(camera),
        scene_(scene),
        options_(options),
        grid_(RayGrid::Build(camera)),
        candidates_(grid_, scene),
        width_(camera.intrinsics().width),
        height_(camera.intrinsics().height) {}

  // Mean reflectance per pixel, row-major.
  std::vector<float> Render() const {
    std::vector<float> image(static_cast<std::size_t>(width_) * height_);
    // Bands go to whichever thread is free; a band's pixels are computed the same way
    // whichever thread takes it.
    const int bands = (height_ + kBandRows - 1) / kBandRows;
    std::atomic<int> next{0};
    const auto work = [&] {
      PixelIntegrator integrator(scene_, options_);
      std::vector<CornerSample> upper(width_ + 1), lower(width_ + 1);
      for (int band = next++; band < bands; band = next++) {
        const int y0 = band * kBandRows, y1 = std::min(height_, y0 + kBandRows);
        CornerRow(y0, &upper);
        for (int y = y0; y < y1; ++y) {
          CornerRow(y + 1, &lower);
          float* row = image.data() + static_cast<std::size_t>(y) * width_;
          for (int x = 0; x < width_; ++x) {
            row[x] = static_cast<float>(Pixel(x, y, &upper, &lower, &integrator));
          }
          std::swap(upper, lower);
        }
      }
    };
    const int threads = std::min(options_.threads, bands);
    std::vector<std::thread> pool;
    for (int i = 1; i < threads; ++i) pool.emplace_back(work);
    work();
    for (std::thread& t : pool) t.join();
    return image;
  }

 private:
  void Trace(int x, int y, CornerSample* c) const {
    if (!c->valid) return;
    const auto [candidates, n] = candidates_.At(x, y);
    c->hit = scene_.Trace(c->ray, candidates, n);
  }

  // The rays and hits of pixel-corner row y (v = y - 0.5).
  void CornerRow(int y, std::vector<CornerSample>* row) const {
    for (int x = 0; x <= width_; ++x) {
      CornerSample& c = (*row)[x];
      grid_.CornerRay(x, y, &c.ray, &c.error_px, &c.valid);
      Trace(x, y, &c);
    }
  }

  // The reflectance of the whole pixel if it is flat: its corners see one look, the surface
  // is uniform over the footprint (grown by the corners' ray errors), and nothing else
  // shows in between: every other surface lies behind, or the centre sees the same look.
  std::optional<double> Flat(const std::array<CornerSample*, 4>& c, const std::uint32_t* candidates,
                             int n) const {
    const std::uint64_t label = c[0]->hit.look.label;
    for (int k = 1; k < 4; ++k) {
      if (c[k]->hit.look.label != label) return std::nullopt;
    }
    const int s = c[0]->hit.surface;
    if (s >= 0) {
      const double error_px =
          std::max({c[0]->error_px, c[1]->error_px, c[2]->error_px, c[3]->error_px});
      if (!scene_.UniformOver(scene_.surfaces()[s],
                              {c[0]->hit.p_surface, c[1]->hit.p_surface, c[2]->hit.p_surface,
                               c[3]->hit.p_surface},
                              error_px)) {
        return std::nullopt;
      }
    }
    if (!InFrontOverPixel(scene_, c, candidates, n)) {
      const Eigen::Vector3d centre = c[0]->ray + c[1]->ray + c[2]->ray + c[3]->ray;
      if (scene_.Trace(centre, candidates, n).look.label != label) return std::nullopt;
    }
    return c[0]->hit.look.reflectance;
  }

  double Pixel(int x, int y, std::vector<CornerSample>* upper, std::vector<CornerSample>* lower,
               PixelIntegrator* integrator) const {
    const std::array<CornerSample*, 4> c = {&(*upper)[x], &(*upper)[x + 1], &(*lower)[x],
                                            &(*lower)[x + 1]};
    const auto [candidates, n] = candidates_.At(x, y);
    if (c[0]->valid && c[1]->valid && c[2]->valid && c[3]->valid) {
      if (const std::optional<double> flat = Flat(c, candidates, n)) return *flat;
      // An edge pixel: exact corner rays (kept for the neighbours that share them).
      const std::array<std::array<int, 2>, 4> xy = {{{x, y}, {x + 1, y}, {x, y + 1}, {x + 1, y + 1}}};
      bool refined = false;
      for (int k = 0; k < 4; ++k) {
        if (c[k]->error_px == 0.0) continue;
        c[k]->valid = grid_.ExactCornerRay(xy[k][0], xy[k][1], &c[k]->ray);
        c[k]->error_px = 0.0;
        Trace(xy[k][0], xy[k][1], c[k]);
        refined = true;
      }
      if (c[0]->valid && c[1]->valid && c[2]->valid && c[3]->valid) {
        if (refined) {
          if (const std::optional<double> flat = Flat(c, candidates, n)) return *flat;
        }
        return integrator->Integrate(c, candidates, n);
      }
    }
    // On the rim of the lens's valid region: the centre ray alone, black outside.
    Eigen::Vector3d ray;
    if (!camera_.Unproject(Eigen::Vector2d(x, y), &ray)) return 0.0;
    return scene_.Trace(ray, candidates, n).look.reflectance;
  }

  const CameraModel& camera_;
  const Scene& scene_;
  const CameraRenderOptions& options_;
  const RayGrid grid_;
  const TileCandidates candidates_;
  const int width_;
  const int height_;
};
// ------------------------------------------------------------------------------------------
// The camera response.

// Runs fn(begin, end) over [0, n) split into `threads` contiguous ranges.
template <typename Fn>
void ParallelFor(int n, int threads, const Fn& fn) {
  threads = std::max(1, std::min(threads, n));
  std::vector<std::thread> pool;
  const auto begin = [&](int i) { return static_cast<int>(static_cast<long long>(n) * i / threads); };
  for (int i = 1; i < threads; ++i) pool.emplace_back([&, i] { fn(begin(i), begin(i + 1)); });
  fn(0, begin(1));
  for (std::thread& t : pool) t.join();
}

// Illumination x gradient x vignetting, per pixel.
void Illuminate(const CameraModel& camera, const CameraRenderOptions& o, std::vector<float>* image) {
  const int width = camera.intrinsics().width, height = camera.intrinsics().height;
  const double angle = o.illumination_gradient_direction_deg * std::numbers::pi / 180.0;
  const Eigen::Vector2d dir(std::cos(angle), std::sin(angle));
  // The gradient runs between the extreme pixel centres along dir, so that the brightest
  // and the darkest pixel differ by exactly the ratio.
  double lo = kInf, hi = -kInf;
  for (const Eigen::Vector2d& corner : {Eigen::Vector2d(0, 0), Eigen::Vector2d(width - 1, 0),
                                       Eigen::Vector2d(0, height - 1),
                                       Eigen::Vector2d(width - 1, height - 1)}) {
    lo = std::min(lo, corner.dot(dir));
    hi = std::max(hi, corner.dot(dir));
  }
  // exp(log_ratio (s - 0.5)) with s linear in (u, v) factors into a column and a row term.
  const double log_ratio = std::log(o.illumination_gradient_ratio);
  const double scale = hi > lo ? log_ratio / (hi - lo) : 0.0;
  std::vector<double> column_gain(width), row_gain(height);
  for (int x = 0; x < width; ++x) column_gain[x] = std::exp(scale * x * dir.x());
  for (int y = 0; y < height; ++y) {
    row_gain[y] = o.illumination * std::exp(scale * (y * dir.y() - lo) - 0.5 * log_ratio);
  }
  const Eigen::Vector2d principal(camera.intrinsics().cx, camera.intrinsics().cy);
  double r2_max = 0.0;
  for (const Eigen::Vector2d& corner : {Eigen::Vector2d(-0.5, -0.5), Eigen::Vector2d(width - 0.5, -0.5),
                                        Eigen::Vector2d(-0.5, height - 0.5),
                                        Eigen::Vector2d(width - 0.5, height - 0.5)}) {
    r2_max = std::max(r2_max, (corner - principal).squaredNorm());
  }
  ParallelFor(height, o.threads, [&](int y0, int y1) {
    for (int y = y0; y < y1; ++y) {
      float* row = image->data() + static_cast<std::size_t>(y) * width;
      const double dy2 = (y - principal.y()) * (y - principal.y());
      for (int x = 0; x < width; ++x) {
        const double r2 = (x - principal.x()) * (x - principal.x()) + dy2;
        const double vignette = 1.0 - o.vignetting * r2 / r2_max;
        row[x] = static_cast<float>(row[x] * row_gain[y] * column_gain[x] * vignette);
      }
    }
  });
}

// Separable Gaussian blur, the kernel integrated over each pixel (so that any sigma,
// however small, keeps the total and the symmetry), clamped at the borders.
void Blur(int width, int height, double sigma, int threads, std::vector<float>* image) {
  // 4 sigma: the tails beyond hold 6e-5 of the weight, below a 16-bit grey step.
  const int radius = std::max(1, static_cast<int>(std::ceil(4.0 * sigma)));
  std::vector<double> kernel(2 * radius + 1);
  double total = 0.0;
  for (int k = -radius; k <= radius; ++k) {
    const double w = 0.5 * (std::erf((k + 0.5) / (std::sqrt(2.0) * sigma)) -
                            std::erf((k - 0.5) / (std::sqrt(2.0) * sigma)));
    kernel[k + radius] = w;
    total += w;
  }
  for (double& w : kernel) w /= total;
  std::vector<float> tmp(image->size());
  // Along rows, then across them whole rows at a time (cache-friendly).
  ParallelFor(height, threads, [&](int y0, int y1) {
    for (int y = y0; y < y1; ++y) {
      const float* src = image->data() + static_cast<std::size_t>(y) * width;
      float* dst = tmp.data() + static_cast<std::size_t>(y) * width;
      for (int x = 0; x < width; ++x) {
        double sum = 0.0;
        for (int k = -radius; k <= radius; ++k) {
          sum += kernel[k + radius] * src[std::clamp(x + k, 0, width - 1)];
        }
        dst[x] = static_cast<float>(sum);
      }
    }
  });
  ParallelFor(height, threads, [&](int y0, int y1) {
    std::vector<double> sum(width);
    for (int y = y0; y < y1; ++y) {
      std::fill(sum.begin(), sum.end(), 0.0);
      for (int k = -radius; k <= radius; ++k) {
        const float* src = tmp.data() + static_cast<std::size_t>(std::clamp(y + k, 0, height - 1)) * width;
        const double w = kernel[k + radius];
        for (int x = 0; x < width; ++x) sum[x] += w * src[x];
      }
      float* dst = image->data() + static_cast<std::size_t>(y) * width;
      for (int x = 0; x < width; ++x) dst[x] = static_cast<float>(sum[x]);
    }
  });
}

// The JPEG luminance quantisation table (ITU-T T.81 Annex K, Table K.1), row-major.
constexpr std::array<int, 64> kJpegLuminance = {
    16, 11, 10, 16, 24,  40,  51,  61,  12, 12, 14, 19, 26,  58,  60,  55,
    14, 13, 16, 24, 40,  57,  69,  56,  14, 17, 22, 29, 51,  87,  80,  62,
    18, 22, 37, 56, 68,  109, 103, 77,  24, 35, 55, 64, 81,  104, 113, 92,
    49, 64, 78, 87, 103, 121, 120, 101, 72, 92, 95, 98, 112, 100, 103, 99};

// Encodes and decodes `grey` (8-bit scale, row-major) as a JPEG's 8 x 8 luminance blocks
// would be at `quality`: level shift, DCT, quantisation with the IJG-scaled table, inverse.
// Partial blocks at the right and bottom are padded by repeating the edge.
void JpegQuantise(int width, int height, int quality, int threads, std::vector<float>* grey) {
  std::array<double, 64> q;
  const int scale = quality < 50 ? 5000 / quality : 200 - 2 * quality;  // IJG's mapping
  for (int i = 0; i < 64; ++i) q[i] = std::clamp((kJpegLuminance[i] * scale + 50) / 100, 1, 255);
  // Orthonormal DCT-II basis: c[k][x] = a(k) cos((2x + 1) k pi / 16).
  std::array<std::array<double, 8>, 8> c;
  for (int k = 0; k < 8; ++k) {
    for (int x = 0; x < 8; ++x) {
      c[k][x] = (k == 0 ? std::sqrt(0.125) : 0.5) * std::cos((2 * x + 1) * k * std::numbers::pi / 16);
    }
  }
  const int block_rows = (height + 7) / 8, block_cols = (width + 7) / 8;
  ParallelFor(block_rows, threads, [&](int b0, int b1) {
    for (int by = b0; by < b1; ++by) {
      for (int bx = 0; bx < block_cols; ++bx) {
        std::array<std::array<double, 8>, 8> f, g;
        for (int y = 0; y < 8; ++y) {
          const int yy = std::min(by * 8 + y, height - 1);
          for (int x = 0; x < 8; ++x) {
            const int xx = std::min(bx * 8 + x, width - 1);
            f[y][x] = (*grey)[static_cast<std::size_t>(yy) * width + xx] - 128.0;
          }
        }
        // Rows, then columns: g = C f C^T, quantised; then f = C^T g C.
        for (int y = 0; y < 8; ++y) {
          for (int k = 0; k < 8; ++k) {
            double s = 0.0;
            for (int x = 0; x < 8; ++x) s += c[k][x] * f[y][x];
            g[y][k] = s;
          }
        }
        for (int k = 0; k < 8; ++k) {
          for (int l = 0; l < 8; ++l) {
            double s = 0.0;
            for (int y = 0; y < 8; ++y) s += c[l][y] * g[y][k];
            f[l][k] = std::round(s / q[l * 8 + k]) * q[l * 8 + k];
          }
        }
        for (int l = 0; l < 8; ++l) {
          for (int x = 0; x < 8; ++x) {
            double s = 0.0;
            for (int k = 0; k < 8; ++k) s += c[k][x] * f[l][k];
            g[l][x] = s;
          }
        }
        for (int y = 0; y < 8 && by * 8 + y < height; ++y) {
          for (int x = 0; x < 8 && bx * 8 + x < width; ++x) {
            double s = 0.0;
            for (int l = 0; l < 8; ++l) s += c[l][y] * g[l][x];
            (*grey)[static_cast<std::size_t>(by * 8 + y) * width + bx * 8 + x] =
                static_cast<float>(s + 128.0);
          }
        }
      }
    }
  });
}

// Linear light to grey levels: gamma, then noise, then JPEG, then rounding.
void Encode(int width, int height, const CameraRenderOptions& o, std::uint64_t seed,
            std::vector<float>* image, CameraFrame* frame) {
  constexpr double kFullScale8 = 255.0;
  const double inverse_gamma = 1.0 / o.gamma;
  ParallelFor(height, o.threads, [&](int y0, int y1) {
    for (int y = y0; y < y1; ++y) {
      // One stream per row: the same numbers whichever thread draws them.
      std::mt19937_64 rng(Mix(Mix(seed, kNoiseStream), static_cast<std::uint64_t>(y)));
      std::normal_distribution<double> normal;
      float* row = image->data() + static_cast<std::size_t>(y) * width;
      for (int x = 0; x < width; ++x) {
        const double linear = std::clamp(static_cast<double>(row[x]), 0.0, 1.0);
        double grey = kFullScale8 * (o.gamma == 1.0 ? linear : std::pow(linear, inverse_gamma));
        if (o.noise_sigma > 0.0) grey += o.noise_sigma * normal(rng);
        row[x] = static_cast<float>(grey);
      }
    }
  });
  if (o.jpeg_quality > 0) JpegQuantise(width, height, o.jpeg_quality, o.threads, image);
  frame->bit_depth = o.bit_depth;
  if (o.bit_depth == 8) {
    frame->image8 = Image8(width, height);
    for (std::size_t i = 0; i < image->size(); ++i) {
      frame->image8.pixels[i] =
          static_cast<std::uint8_t>(std::lround(std::clamp((*image)[i], 0.0f, 255.0f)));
    }
  } else {
    // 16-bit full scale is 257 x the 8-bit one (255 * 257 = 65535).
    constexpr double kEightToSixteen = 257.0;
    frame->image16 = Image16(width, height);
    for (std::size_t i = 0; i < image->size(); ++i) {
      frame->image16.pixels[i] = static_cast<std::uint16_t>(
          std::lround(std::clamp(kEightToSixteen * (*image)[i], 0.0, 65535.0)));
    }
  }
}

// ------------------------------------------------------------------------------------------
// Occluders.

// Along the line of sight, between 30% and 70% of the way to the feature: clear of the
// board and of the lens.
constexpr double kOccluderMinFraction = 0.3;
constexpr double kOccluderMaxFraction = 0.7;
// Sides of 1:2 to 2:1.
constexpr double kOccluderMaxAspect = 2.0;
// Greys from near black to near white.
constexpr double kOccluderMinGrey = 0.05;
constexpr double kOccluderMaxGrey = 0.95;
// Without a visible feature: 1-5 m in front, the scale of a station.
constexpr double kOccluderMinDistanceM = 1.0;
constexpr double kOccluderMaxDistanceM = 5.0;

std::vector<StationSurface> PlaceOccluders(const CameraModel& camera,
                                           const Rigid3d& T_station_camera,
                                           const StationLayout& layout,
                                           const CameraRenderOptions& o, std::uint64_t seed) {
  std::vector<StationSurface> occluders;
  if (o.occluder_count == 0) return occluders;
  const std::vector<RenderedFeature> visible =
      VisibleCameraFeatures(camera, T_station_camera, layout, {}, o.feature_margin_px);
  const Rigid3d T_camera_station = T_station_camera.Inverse();
  std::mt19937_64 rng(Mix(seed, kOccluderStream));
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  const CameraIntrinsics& c = camera.intrinsics();
  for (int i = 0; i < o.occluder_count; ++i) {
    Eigen::Vector3d centre_camera;
    if (!visible.empty()) {
      const RenderedFeature& f = visible[static_cast<std::size_t>(unit(rng) * visible.size()) %
                                         visible.size()];
      const StationBoard& b = layout.boards[f.board_index];
      const Eigen::Vector2d& p_board = b.board.features()[f.feature_id].p_board;
      const Eigen::Vector3d p_camera =
          T_camera_station * (b.T_station_board * Eigen::Vector3d(p_board.x(), p_board.y(), 0));
      const double fraction =
          kOccluderMinFraction + (kOccluderMaxFraction - kOccluderMinFraction) * unit(rng);
      centre_camera = fraction * p_camera;
    } else {
      Eigen::Vector3d ray;
      const Eigen::Vector2d uv(unit(rng) * c.width - 0.5, unit(rng) * c.height - 0.5);
      if (!camera.Unproject(uv, &ray)) ray = Eigen::Vector3d::UnitZ();
      const double distance =
          kOccluderMinDistanceM + (kOccluderMaxDistanceM - kOccluderMinDistanceM) * unit(rng);
      centre_camera = distance * ray;
    }
    // About occluder_size_px across at the image centre: pixels * distance / focal length.
    const double side_m = o.occluder_size_px * centre_camera.norm() / c.fx;
    const double aspect = std::exp(std::log(kOccluderMaxAspect) * (2 * unit(rng) - 1));
    // Facing the camera, turned by a random angle about the line of sight.
    const Eigen::Vector3d z = -centre_camera.normalized();
    const Eigen::Vector3d any = std::abs(z.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
    const Eigen::Vector3d x0 = z.cross(any).normalized();
    const double spin = 2 * std::numbers::pi * unit(rng);
    const Eigen::Vector3d x = std::cos(spin) * x0 + std::sin(spin) * z.cross(x0);
    Eigen::Matrix3d R_camera_occluder;
    R_camera_occluder << x, z.cross(x), z;
    StationSurface occluder;
    occluder.id = absl::StrCat("occluder_", i);
    occluder.T_station_surface = T_station_camera * Rigid3d(R_camera_occluder, centre_camera);
    occluder.size_m = side_m * Eigen::Vector2d(std::sqrt(aspect), 1.0 / std::sqrt(aspect));
    occluder.reflectivity = kOccluderMinGrey + (kOccluderMaxGrey - kOccluderMinGrey) * unit(rng);
    occluders.push_back(occluder);
  }
  return occluders;
}

bool PoseFinite(const Rigid3d& T) {
  return T.rotation().coeffs().allFinite() && T.translation().allFinite();
}

absl::Status CheckLayout(const StationLayout& layout) {
  const absl::Status reflectivity =
      CheckClosed("floor_reflectivity", layout.floor_reflectivity, 0.0, 1.0);
  if (!reflectivity.ok()) return reflectivity;
  for (std::size_t i = 0; i < layout.boards.size(); ++i) {
    if (!PoseFinite(layout.boards[i].T_station_board)) {
      return absl::InvalidArgumentError(
          absl::StrCat("boards[", i, "] '", layout.boards[i].id, "': pose is not finite"));
    }
  }
  for (std::size_t i = 0; i < layout.surfaces.size(); ++i) {
    const StationSurface& s = layout.surfaces[i];
    const std::string name = absl::StrCat("surfaces[", i, "] '", s.id, "'");
    if (!PoseFinite(s.T_station_surface)) {
      return absl::InvalidArgumentError(absl::StrCat(name, ": pose is not finite"));
    }
    if (!(s.size_m.allFinite() && s.size_m.minCoeff() > 0.0)) {
      return absl::InvalidArgumentError(
          absl::StrCat(name, ": size_m = [", s.size_m.x(), ", ", s.size_m.y(),
                       "]: must be finite and > 0"));
    }
    const absl::Status r = CheckClosed(absl::StrCat(name, ".reflectivity"), s.reflectivity, 0, 1);
    if (!r.ok()) return r;
  }
  return absl::OkStatus();
}

}  // namespace

absl::Status CameraRenderOptions::Validate() const {
  const std::pair<absl::string_view, std::array<double, 3>> closed[] = {
      {"edge_probes_per_side", {double(edge_probes_per_side), kMinEdgeProbes, kMaxEdgeProbes}},
      {"edge_tolerance_px", {edge_tolerance_px, kMinEdgeTolerancePx, kMaxEdgeTolerancePx}},
      {"max_subdivision_depth", {double(max_subdivision_depth), 0, kMaxSubdivisionDepth}},
      {"white_reflectance", {white_reflectance, 0, 1}},
      {"board_back_reflectance", {board_back_reflectance, 0, 1}},
      {"background_reflectance", {background_reflectance, 0, 1}},
      {"illumination_gradient_ratio", {illumination_gradient_ratio, 1, kMaxGradientRatio}},
      {"vignetting", {vignetting, 0, 1}},
      {"blur_sigma_px", {blur_sigma_px, 0, kMaxBlurSigmaPx}},
      {"gamma", {gamma, kMinGamma, kMaxGamma}},
      {"noise_sigma", {noise_sigma, 0, kMaxNoiseSigma}},
      {"occluder_count", {double(occluder_count), 0, kMaxOccluders}},
      {"feature_margin_px", {feature_margin_px, 0, kMaxFeatureMarginPx}},
      {"threads", {double(threads), 1, kMaxThreads}},
  };
  for (const auto& [field, check] : closed) {
    if (absl::Status s = CheckClosed(field, check[0], check[1], check[2]); !s.ok()) return s;
  }
  if (!(black_reflectance >= 0.0 && black_reflectance < white_reflectance)) {
    return OutOfRange("black_reflectance", black_reflectance,
                      absl::StrCat("[0, white_reflectance = ", white_reflectance, ")"));
  }
  if (!(illumination > 0.0 && illumination <= kMaxIllumination)) {
    return OutOfRange("illumination", illumination, absl::StrCat("(0, ", kMaxIllumination, "]"));
  }
  if (!std::isfinite(illumination_gradient_direction_deg)) {
    return absl::InvalidArgumentError(absl::StrCat("illumination_gradient_direction_deg = ",
                                                   illumination_gradient_direction_deg,
                                                   ": must be finite"));
  }
  if (vignetting >= 1.0) return OutOfRange("vignetting", vignetting, "[0, 1)");
  if (jpeg_quality != 0 && (jpeg_quality < kMinJpegQuality || jpeg_quality > kMaxJpegQuality)) {
    return OutOfRange("jpeg_quality", jpeg_quality,
                      absl::StrCat("{0} or [", kMinJpegQuality, ", ", kMaxJpegQuality, "]"));
  }
  if (bit_depth != 8 && bit_depth != 16) return OutOfRange("bit_depth", bit_depth, "{8, 16}");
  if (!(clutter_density > 0.0 && clutter_density <= 1.0)) {
    return OutOfRange("clutter_density", clutter_density, "(0, 1]");
  }
  if (!(occluder_size_px > 0.0 && occluder_size_px <= kMaxOccluderSizePx)) {
    return OutOfRange("occluder_size_px", occluder_size_px,
                      absl::StrCat("(0, ", kMaxOccluderSizePx, "]"));
  }
  return absl::OkStatus();
}

std::vector<RenderedFeature> VisibleCameraFeatures(const CameraModel& camera,
                                                   const Rigid3d& T_station_camera,
                                                   const StationLayout& layout,
                                                   const std::vector<StationSurface>& occluders,
                                                   double margin_px) {
  // Only the geometry of the scene matters here: every look is opaque alike.
  const Scene scene(T_station_camera, layout, occluders, CameraRenderOptions());
  const std::vector<std::uint32_t> all = AllSurfaces(scene);
  const Rigid3d T_camera_station = T_station_camera.Inverse();
  const CameraIntrinsics& c = camera.intrinsics();
  // Sight lines are tested up to just short of the feature, so that a surface through the
  // feature (its own board's plane, a board lying on the floor) does not hide it: 1e-9 of
  // the distance is a nanometre at a metre, far below anything the scene resolves.
  constexpr double kSightLineEnd = 1.0 - 1e-9;
  std::vector<RenderedFeature> visible;
  for (std::size_t b = 0; b < layout.boards.size(); ++b) {
    const StationBoard& board = layout.boards[b];
    // Boards come first in the scene, in layout order.
    const SceneSurface& surface = scene.surfaces()[b];
    if (surface.eye_surface.z() <= 0.0) continue;  // the printed face looks away
    const Rigid3d T_camera_board = T_camera_station * board.T_station_board;
    for (const BoardFeature& f : board.board.features()) {
      const Eigen::Vector3d p_camera =
          T_camera_board * Eigen::Vector3d(f.p_board.x(), f.p_board.y(), 0.0);
      Eigen::Vector2d uv;
      if (!camera.Project(p_camera, &uv)) continue;
      if (!(uv.x() >= -0.5 + margin_px && uv.x() <= c.width - 0.5 - margin_px &&
            uv.y() >= -0.5 + margin_px && uv.y() <= c.height - 0.5 - margin_px)) {
        continue;
      }
      const Hit blocker = scene.Trace(p_camera, all.data(), static_cast<int>(all.size()),
                                      static_cast<int>(b), kSightLineEnd);
      if (blocker.surface >= 0) continue;
      visible.push_back(RenderedFeature{board.id, static_cast<int>(b), f.id, f.kind, uv});
    }
  }
  return visible;
}

absl::StatusOr<CameraFrame> RenderCameraFrame(const CameraModel& camera,
                                              const Rigid3d& T_station_camera,
                                              const StationLayout& layout,
                                              const CameraRenderOptions& options,
                                              std::uint64_t seed) {
  if (absl::Status s = options.Validate(); !s.ok()) return s;
  if (!PoseFinite(T_station_camera)) {
    return absl::InvalidArgumentError("T_station_camera: pose is not finite");
  }
  if (absl::Status s = CheckLayout(layout); !s.ok()) return s;
  CameraFrame frame;
  frame.occluders = PlaceOccluders(camera, T_station_camera, layout, options, seed);
  frame.features = VisibleCameraFeatures(camera, T_station_camera, layout, frame.occluders,
                                         options.feature_margin_px);
  const Scene scene(T_station_camera, layout, frame.occluders, options);
  std::vector<float> image = LinearRenderer(camera, scene, options).Render();
  const int width = camera.intrinsics().width, height = camera.intrinsics().height;
  Illuminate(camera, options, &image);
  if (options.blur_sigma_px > 0.0) Blur(width, height, options.blur_sigma_px, options.threads, &image);
  Encode(width, height, options, seed, &image, &frame);
  return frame;
}

}  // namespace linecal
