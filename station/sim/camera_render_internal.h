#pragma once
// What the parts of the camera renderer share; private to station/sim/camera_render*.cc (the
// contract for everyone else is camera_render.h). The parts, by file:
//   camera_render.cc            option and layout checks, VisibleCameraFeatures,
//                               RenderCameraFrame (the pipeline below, in order)
//   camera_render_occluders.cc  occluders placed per frame
//   camera_render_scene.cc      the scene in the camera frame: labels, wall clutter, looks
//   camera_render_rays.cc       the pixel-corner rays and the surfaces each tile may show
//   camera_render_pixel.cc      integrating one pixel over its area
//   camera_render_image.cc      the linear image, pixel by pixel, over threads
//   camera_render_response.cc   the camera response: illumination, blur, gamma, noise, JPEG

#include <Eigen/Core>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <optional>
#include <utility>
#include <vector>

#include "detectors/boards/board.h"
#include "detectors/core/pose.h"
#include "station/camera/camera_model.h"
#include "station/model/station_layout.h"
#include "station/sim/camera_render.h"

namespace linecal::camera_render_internal {

inline constexpr double kInf = std::numeric_limits<double>::infinity();

// Limits of CameraRenderOptions::edge_probes_per_side (the reasons are in the header's field
// comments); the integrator sizes its probe loop by the upper one.
inline constexpr int kMinEdgeProbes = 2;
inline constexpr int kMaxEdgeProbes = 64;

// ------------------------------------------------------------------------------------------
// Hashing: seeds, per-row noise streams and the procedural clutter.

// The finaliser of SplitMix64: a bijective 64-bit mixer whose outputs pass BigCrush.
inline std::uint64_t Mix(std::uint64_t x) {
  x += 0x9e3779b97f4a7c15ULL;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
  return x ^ (x >> 31);
}

inline std::uint64_t Mix(std::uint64_t a, std::uint64_t b) { return Mix(a ^ Mix(b)); }

// Uniform in [0, 1) from the top 53 bits of a hash.
inline double Unit(std::uint64_t h) { return static_cast<double>(h >> 11) * 0x1.0p-53; }

// Independent streams drawn from the frame seed.
inline constexpr std::uint64_t kNoiseStream = 1;
inline constexpr std::uint64_t kOccluderStream = 2;

// ------------------------------------------------------------------------------------------
// The scene in the camera frame (camera_render_scene.cc).

// What a ray sees: an id (equal ids = one region of one paint; the codes are in
// camera_render_scene.cc) and a reflectance.
inline constexpr std::uint64_t kBackgroundLabel = 0;

struct Look {
  std::uint64_t label = kBackgroundLabel;
  double reflectance = 0.0;
};

// The clutter of one wall: a grid of cells (camera_render_scene.cc), rotated and shifted per
// wall; a cell holds one rectangle or disc with probability `density`.
struct ClutterGrid {
  double density = 0.0;
  std::uint64_t key = 0;
  Eigen::Matrix2d R_grid_surface = Eigen::Matrix2d::Identity();
  Eigen::Vector2d offset_m = Eigen::Vector2d::Zero();
};

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

// The layout's boards (first, in layout order), the occluders, the walls and the floor, as
// planes in the camera frame. Holds pointers into `layout`'s boards: the layout must outlive
// it.
class Scene {
 public:
  Scene(const Rigid3d& T_station_camera, const StationLayout& layout,
        const std::vector<StationSurface>& occluders, const CameraRenderOptions& options);

  const std::vector<SceneSurface>& surfaces() const { return surfaces_; }
  int surface_count() const { return static_cast<int>(surfaces_.size()); }

  // Where the ray t * d_camera (0 < t < max_t) meets the plane of surface s inside its
  // extent.
  static bool Intersect(const SceneSurface& s, const Eigen::Vector3d& d_camera, double max_t,
                        double* t, Eigen::Vector2d* p_surface);

  // What surface s shows at p_surface (a point inside its extent); nullopt where it lets
  // the ray through (holes, off the page).
  std::optional<Look> LookAt(const SceneSurface& s, const Eigen::Vector2d& p_surface) const;

  // True if surface s shows one look over the whole footprint of a pixel whose corners hit
  // it at p (conservative: false when unsure). The footprint lies in the convex hull of
  // the corners' hits; corner rays off by up to error_px pixels move them by about that
  // fraction of the footprint's extent, so the corners' bounding box is grown by twice
  // that.
  bool UniformOver(const SceneSurface& s, const std::array<Eigen::Vector2d, 4>& p,
                   double error_px) const;

  // The nearest opaque hit of the ray t * d_camera among the candidate surfaces, skipping
  // surface `exclude` and hits at t >= max_t; the background look if there is none.
  Hit Trace(const Eigen::Vector3d& d_camera, const std::uint32_t* candidates, int n,
            int exclude = -1, double max_t = kInf) const;

 private:
  std::optional<Look> BoardLook(const SceneSurface& s, Paint paint) const;

  SceneLooks looks_;
  std::vector<SceneSurface> surfaces_;
};

// Scene::Intersect and Scene::Trace are inline: every pixel corner and probe traces.
inline bool Scene::Intersect(const SceneSurface& s, const Eigen::Vector3d& d_camera, double max_t,
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

inline Hit Scene::Trace(const Eigen::Vector3d& d_camera, const std::uint32_t* candidates, int n,
                        int exclude, double max_t) const {
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

// The indices of all the scene's surfaces, as candidates for Scene::Trace.
std::vector<std::uint32_t> AllSurfaces(const Scene& scene);

// ------------------------------------------------------------------------------------------
// The pixel-corner rays: exact on a coarse grid, interpolated in between
// (camera_render_rays.cc). Holds a reference to the camera: it must outlive the grid.

class RayGrid {
 public:
  // The coarse grid if interpolation serves on it, else the fine one.
  static RayGrid Build(const CameraModel& camera);

  RayGrid(const CameraModel& camera, int spacing_px);

  int spacing_px() const { return spacing_px_; }
  int cols() const { return cols_; }
  int rows() const { return rows_; }
  // The cell holding pixel (x, y), or pixel corner (x - 0.5, y - 0.5); corners on the right
  // and bottom edges of the image belong to the last cells.
  int CellX(int x) const { return std::min(x / spacing_px_, cols_ - 1); }
  int CellY(int y) const { return std::min(y / spacing_px_, rows_ - 1); }

  double InterpolatedFraction() const;

  // The node rays at the corners of the block of cells [i0, i1) x [j0, j1): top-left,
  // top-right, bottom-left, bottom-right; false unless interpolation serves in every cell
  // of the block (so its rays are valid and the lens mapping is smooth over it).
  bool BlockRays(int i0, int j0, int i1, int j1, std::array<const Eigen::Vector3d*, 4>* rays) const;

  // The ray of pixel corner (x - 0.5, y - 0.5), 0 <= x <= width, 0 <= y <= height (not
  // unit length), and an upper bound of its error in pixels (0 when exact). Rays of
  // invalid corners: *valid = false.
  void CornerRay(int x, int y, Eigen::Vector3d* ray, double* error_px, bool* valid) const;

  bool ExactCornerRay(int x, int y, Eigen::Vector3d* ray) const;

 private:
  // The ray of image point uv: for a pinhole scaled to z = 1, where the undistorted image
  // is linear in the ray, so that blends of rays are exact rays of blended pixels; for a
  // fisheye (rays may point backwards) of unit length.
  bool Ray(const Eigen::Vector2d& uv, Eigen::Vector3d* ray) const;

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
inline constexpr int kTilePx = 16;

class TileCandidates {
 public:
  TileCandidates(const RayGrid& grid, const Scene& scene);

  // The candidates of the tile holding pixel (x, y) or pixel corner (x - 0.5, y - 0.5);
  // corners on the image's right and bottom edges belong to the last tiles.
  std::pair<const std::uint32_t*, int> At(int x, int y) const {
    const int tx = std::min(x / kTilePx, cols_ - 1), ty = std::min(y / kTilePx, rows_ - 1);
    const std::size_t t = static_cast<std::size_t>(ty) * cols_ + tx;
    return {list_.data() + begin_[t], static_cast<int>(begin_[t + 1] - begin_[t])};
  }

 private:
  static bool MayShow(const SceneSurface& s, const std::array<const Eigen::Vector3d*, 4>& rays);

  const int cells_per_tile_;
  const int cols_;
  const int rows_;
  std::vector<std::uint32_t> begin_;
  std::vector<std::uint32_t> list_;
};

// ------------------------------------------------------------------------------------------
// Integrating one pixel (camera_render_pixel.cc).

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
// Inline: every pixel asks.
inline bool InFrontOverPixel(const Scene& scene, const std::array<CornerSample*, 4>& c,
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

// Integrates pixels of one scene; one per thread (it keeps the current pixel's state).
class PixelIntegrator {
 public:
  PixelIntegrator(const Scene& scene, const CameraRenderOptions& options)
      : scene_(scene),
        probes_(options.edge_probes_per_side),
        tolerance_(options.edge_tolerance_px),
        max_depth_(options.max_subdivision_depth) {}

  // Mean reflectance over the pixel whose corners (exact rays) are c[0] (top-left), c[1]
  // (top-right), c[2] (bottom-left), c[3] (bottom-right).
  double Integrate(const std::array<CornerSample*, 4>& c, const std::uint32_t* candidates, int n);

 private:
  static constexpr int kMaxLoop = 4 * kMaxEdgeProbes;

  // The surface the pixel's corners all hit, if it is in front over the whole pixel.
  const SceneSurface* FrontSurface(const std::array<CornerSample*, 4>& c) const;

  // What the ray at pixel-local (s, t) sees.
  Look Eval(const Eigen::Vector2d& st) const;

  // Position of loop sample k of the cell at `origin` with side `size`, `per_side` samples
  // per side, starting at the top-left corner and running through top-right, bottom-right
  // and bottom-left: positively oriented in (s, t).
  static Eigen::Vector2d LoopPoint(const Eigen::Vector2d& origin, double size, int per_side, int k);

  // Shrinks [a, b] (labels la != lb) around the label change; false if a third label shows.
  bool Bisect(Eigen::Vector2d a, std::uint64_t la, Eigen::Vector2d b, std::uint64_t lb,
              Eigen::Vector2d* crossing) const;

  // Integral of reflectance over the cell (area in pixels^2 times reflectance). `corners`:
  // the looks at the loop's four corners.
  double Cell(const Eigen::Vector2d& origin, double size, int depth,
              const std::array<Look, 4>& corners);

  // The cell split by one arc: the loop changes from look A to B after sample k1 and back
  // after sample k2. False when the arc is not smooth enough to integrate (the caller then
  // splits the cell).
  bool Arc(const Eigen::Vector2d& origin, double size, int per_side,
           const std::array<Look, kMaxLoop>& loop, int k1, int k2, double* value) const;

  const Scene& scene_;
  const int probes_;
  const double tolerance_;
  const int max_depth_;
  std::array<const Eigen::Vector3d*, 4> rays_{};
  const std::uint32_t* candidates_ = nullptr;
  int n_candidates_ = 0;
  const SceneSurface* front_ = nullptr;
  std::array<Eigen::Vector2d, 4> q_;   // the corners' hits on *front_
  std::array<double, 4> inverse_t_{};  // 1 / their depths along the corner rays
};

// ------------------------------------------------------------------------------------------
// The linear image (camera_render_image.cc).

// Mean reflectance per pixel of `camera` looking at `scene`, row-major, on options.threads
// threads (the same numbers whichever thread computes a pixel).
std::vector<float> RenderLinearImage(const CameraModel& camera, const Scene& scene,
                                     const CameraRenderOptions& options);

// ------------------------------------------------------------------------------------------
// The camera response (camera_render_response.cc).

// Illumination x gradient x vignetting, per pixel of `image` (the camera's size, row-major).
void Illuminate(const CameraModel& camera, const CameraRenderOptions& o, std::vector<float>* image);

// Separable Gaussian blur, the kernel integrated over each pixel (so that any sigma,
// however small, keeps the total and the symmetry), clamped at the borders.
void Blur(int width, int height, double sigma, int threads, std::vector<float>* image);

// Linear light to grey levels: gamma, then noise (from `seed`), then JPEG, then rounding into
// frame's 8- or 16-bit image. Overwrites *image.
void Encode(int width, int height, const CameraRenderOptions& o, std::uint64_t seed,
            std::vector<float>* image, CameraFrame* frame);

// ------------------------------------------------------------------------------------------
// Occluders (camera_render_occluders.cc).

// o.occluder_count flat grey rectangles facing the camera, each on the line of sight to a
// random visible feature (or, with none visible, 1-5 m in front), drawn from `seed`.
std::vector<StationSurface> PlaceOccluders(const CameraModel& camera,
                                           const Rigid3d& T_station_camera,
                                           const StationLayout& layout,
                                           const CameraRenderOptions& o, std::uint64_t seed);

}  // namespace linecal::camera_render_internal
