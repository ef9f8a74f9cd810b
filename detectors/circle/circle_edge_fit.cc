#include "detectors/circle/circle_edge_fit.h"

#include <Eigen/Cholesky>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numbers>
#include <span>
#include <vector>

#include "detectors/common/image_filters.h"

namespace linecal {
namespace {

// A part of the image as floats, for bilinear sampling in image coordinates.
struct Patch {
  ImageF image;
  Eigen::Vector2d origin = Eigen::Vector2d::Zero();  // image coordinates of its pixel (0, 0)

  float At(double u, double v) const {
    return SampleBilinear(image, u - origin.x(), v - origin.y());
  }
  // True when uv lies on the patch's pixel centres' area. The patch covers every sample the
  // search can take, except where the image ends: a point off the patch is off the image,
  // where At() would replicate the border pixels.
  bool Inside(const Eigen::Vector2d& uv) const {
    const Eigen::Vector2d p = uv - origin;
    return p.x() >= 0.0 && p.y() >= 0.0 && p.x() <= image.width - 1 && p.y() <= image.height - 1;
  }
};

// The pixels that the edge search around `ellipse` can reach, as floats: its bounding box,
// widened by the first pass's window (0.35 of the radius, below half the semi-major axis)
// and the profile's end samples (a few pixels).
Patch MakePatch(const ImageView8& image, const Ellipse& ellipse) {
  const double reach = 1.5 * ellipse.semi_major + 4.0;
  // Clamped in floating point before the conversion, which a degenerate ellipse (one near
  // the board's vanishing line) would overflow.
  auto clamp_to = [](double v, int lo, int hi) {
    return static_cast<int>(std::clamp(v, static_cast<double>(lo), static_cast<double>(hi)));
  };
  const int x0 = clamp_to(std::floor(ellipse.centre.x() - reach), 0, image.width - 1);
  const int y0 = clamp_to(std::floor(ellipse.centre.y() - reach), 0, image.height - 1);
  const int x1 = clamp_to(std::ceil(ellipse.centre.x() + reach), x0, image.width - 1);
  const int y1 = clamp_to(std::ceil(ellipse.centre.y() + reach), y0, image.height - 1);
  const ImageView8 crop{image.Row(y0) + x0, x1 - x0 + 1, y1 - y0 + 1, image.stride_bytes};
  return Patch{GaussianBlur(crop, 0.0), Eigen::Vector2d(x0, y0)};
}

// How one pass searches for the edge along each ray.
struct EdgeSearch {
  double window_fraction = 0.35;  // of the seed's radius along the ray, on either side
  double max_window_px = 0.0;     // 0: no limit
  int samples_per_side = 0;       // profile samples per side at most; 0: every 0.5 px
};

// The finest profile step, pixels: fine enough to locate the derivative's peak of an edge
// blurred by 0.5 px with a parabola.
constexpr double kProfileStepPx = 0.5;

// The fourfold harmonic of the points' radial departure from `e` (EdgeShape), in e's frame,
// where e is the unit circle: least squares of |q| - 1 on 1, cos 4 phi and sin 4 phi, which
// stays exact when the rays are spread unevenly in phi (an elongated ellipse).
EdgeShape FourfoldDeparture(const Ellipse& e, const std::vector<Eigen::Vector2d>& points) {
  const double c = std::cos(e.angle_rad);
  const double s = std::sin(e.angle_rad);
  // Normal equations of the three terms; cos 4 phi and sin 4 phi as the fourth power of the
  // unit vector (x, y) / |q|, without trigonometry.
  Eigen::Matrix3d normal = Eigen::Matrix3d::Zero();
  Eigen::Vector3d rhs = Eigen::Vector3d::Zero();
  double sum = 0.0;
  double sum_sq = 0.0;
  for (const Eigen::Vector2d& p : points) {
    const Eigen::Vector2d d = p - e.centre;
    const double x = (c * d.x() + s * d.y()) / e.semi_major;
    const double y = (c * d.y() - s * d.x()) / e.semi_minor;
    const double rho = std::hypot(x, y);
    const double c2 = (x * x - y * y) / (rho * rho);
    const double s2 = 2.0 * x * y / (rho * rho);
    const Eigen::Vector3d term(1.0, c2 * c2 - s2 * s2, 2.0 * c2 * s2);
    const double departure = rho - 1.0;
    normal += term * term.transpose();
    rhs += departure * term;
    sum += departure;
    sum_sq += departure * departure;
  }
  const Eigen::Vector3d coef = normal.ldlt().solve(rhs);
  // The harmonic's share: the sum of squares the two terms explain beyond the mean.
  const double n = static_cast<double>(points.size());
  const double variance = sum_sq - sum * sum / n;
  const double explained = coef.dot(rhs) - sum * sum / n;
  EdgeShape shape;
  shape.fourfold_px = coef.tail<2>().norm() * std::sqrt(e.semi_major * e.semi_minor);
  shape.fourfold_share = variance > 0.0 ? explained / variance : 0.0;
  return shape;
}

// One pass of edge points along rays from seed's centre and an ellipse fit to them, with
// the outliers (neighbouring edges, occlusion) removed.
// *shape (when not null): how the edge points depart from the first fit, before the outliers
// are removed.
std::optional<Ellipse> FitCircleEdge(const Patch& patch, const Ellipse& seed, bool light,
                                     std::span<const Eigen::Vector2d> directions,
                                     const EdgeSearch& search, int min_contrast,
                                     EdgeShape* shape = nullptr) {
  const int rays = static_cast<int>(directions.size());
  std::vector<Eigen::Vector2d> points;
  points.reserve(rays);
  std::vector<float> profile;
  std::vector<double> xs, ys;
  const double sign = light ? 1.0 : -1.0;  // light: grey falls outwards
  const double axis_cos = std::cos(seed.angle_rad);
  const double axis_sin = std::sin(seed.angle_rad);
  for (int k = 0; k < rays; ++k) {
    const Eigen::Vector2d& u = directions[k];
    // The ray in the seed's axes: cos and sin of (theta - angle).
    const double c = (u.x() * axis_cos + u.y() * axis_sin) / seed.semi_major;
    const double s = (u.y() * axis_cos - u.x() * axis_sin) / seed.semi_minor;
    const double rho = 1.0 / std::sqrt(c * c + s * s);
    // At least 1.5 px: the seed's error for the smallest circles.
    double window = std::max(1.5, search.window_fraction * rho);
    if (search.max_window_px > 0.0) window = std::min(window, search.max_window_px);
    const double step = search.samples_per_side > 0
                            ? std::max(kProfileStepPx, window / search.samples_per_side)
                            : kProfileStepPx;
    const int n = static_cast<int>(std::ceil(window / step));
    // A profile that leaves the image would see the border pixels replicated, which moves the
    // gradient peak of an edge near the border: such a ray gives no point (a circle cut by
    // the border is fitted to the part of its edge in view).
    if (!patch.Inside(seed.centre + (rho - (n + 1) * step) * u) ||
        !patch.Inside(seed.centre + (rho + (n + 1) * step) * u)) {
      continue;
    }
    // The sample points first, then their grey levels, in loops of their own: the samples
    // do not wait on one another.
    const int count = 2 * n + 3;
    profile.resize(count);
    xs.resize(count);
    ys.resize(count);
    for (int j = -n - 1; j <= n + 1; ++j) {
      const double t = rho + j * step;
      xs[j + n + 1] = seed.centre.x() + t * u.x();
      ys[j + n + 1] = seed.centre.y() + t * u.y();
    }
    for (int i = 0; i < count; ++i) profile[i] = patch.At(xs[i], ys[i]);
    auto derivative = [&](int j) {
      return sign * (profile[j + n] - profile[j + n + 2]);  // P(j - 1) - P(j + 1)
    };
    int best = -n;
    for (int j = -n + 1; j <= n; ++j) {
      if (derivative(j) > derivative(best)) best = j;
    }
    // The derivative peak of a printed edge (at least min_contrast over a blur of a couple
    // of pixels) exceeds a quarter of min_contrast per pixel; weaker peaks are noise.
    if (best == -n || best == n || derivative(best) < 0.25 * min_contrast * 2.0 * step) continue;
    const double d0 = derivative(best - 1);
    const double d1 = derivative(best);
    const double d2 = derivative(best + 1);
    const double curvature = d0 - 2.0 * d1 + d2;
    if (!(curvature < 0.0)) continue;
    const double delta = 0.5 * (d0 - d2) / curvature;
    points.push_back(seed.centre + (rho + (best + delta) * step) * u);
  }
  // Half the rays: a circle half hidden or half on a neighbour is not measured.
  if (static_cast<int>(points.size()) < rays / 2) return std::nullopt;
  std::optional<Ellipse> fit = FitEllipse(points);
  if (!fit) return std::nullopt;
  const Eigen::Matrix3d conic = fit->Conic();
  std::vector<double> residuals(points.size());
  for (std::size_t i = 0; i < points.size(); ++i) residuals[i] = SampsonDistance(conic, points[i]);
  std::vector<double> sorted = residuals;
  std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
  // 3 robust sigmas (1.4826 median absolute residual), and never below 0.2 px, the noise
  // of a single edge point at sigma 4.
  if (shape != nullptr) {
    *shape = FourfoldDeparture(*fit, points);
    shape->median_residual_px = sorted[sorted.size() / 2];
  }
  const double limit = std::max(0.2, 3.0 * 1.4826 * sorted[sorted.size() / 2]);
  std::vector<double> weights(points.size());
  int kept = 0;
  for (std::size_t i = 0; i < points.size(); ++i) {
    weights[i] = residuals[i] <= limit ? 1.0 : 0.0;
    kept += residuals[i] <= limit;
  }
  if (kept < rays / 2) return std::nullopt;
  if (kept < static_cast<int>(points.size())) fit = FitEllipse(points, weights);
  return fit;
}

// How far past a circle's edge its blur reaches the page (3 sigma of docs/acceptance.md's
// hardest blur, 1.5 px, is 4.5 px; at 2.5 px the share left out beyond is symmetric about
// the centre, so it only dims the edge), and the page ring's least width.
constexpr double kCentroidBlurReachPx = 2.5;
constexpr double kCentroidRingPx = 2.0;
constexpr double kCentroidMinRingPx = 1.0;
constexpr double kNeighbourBlurPx = 1.5;

// The model fit's start (a blur of a pixel: the renders' fits end at 0.6-1.2 px, the
// corpus photos' at 0.3-0.65 px), its iterations at most (it takes 2-4), and the centre's
// step that ends it: near the optimum each step is a fraction of the last, and the renders'
// RMS is the same to 0.0001 px as when run to a step of 0.001 px, one pass fewer.
constexpr double kModelStartSigmaPx = 1.0;
constexpr int kModelMaxIterations = 20;
constexpr double kModelCentreTolerancePx = 5e-3;
// Levenberg-Marquardt's damping at the start, and where it gives up (steps a millionth of
// the Gauss-Newton step's scale that still do not lower the cost).
constexpr double kModelStartDamping = 1e-3;
constexpr double kModelMaxDamping = 1e6;
// The page ring's least scatter about its plane (Levels::noise, grey levels RMS) for the
// model fit. The centroid, linear in the grey levels, is immune to the pixel grid, which
// leaves the model fit's edge 0.003-0.005 px off on clean renders (blur 0.5-1.0, against the
// centroid's 0.002-0.003), while noise moves the centroid by about 0.0055 px and the model
// fit by 0.0036 px per grey level (circle_grid_detector_test's pose grid at blur 1.0): they
// cross between 0.4 and 1.2 grey levels of noise. The scatter also counts what the plane does
// not explain (a blur of 1.5 px still reaching the ring: 2 grey levels on clean renders).
constexpr double kModelMinNoise = 1.0;
// Beyond this many sigmas from the edge the pixel counts as all print or all page: the
// Gaussian's tail there is 0.0013 of the contrast (0.3 grey levels at a contrast of 200),
// below the noise of the images the fit is used on (kModelMinNoise), and the edge's pixels,
// the costly ones, are a quarter fewer than at 4 sigmas (the renders' RMS the same to 0.0001
// px).
constexpr double kModelEdgeReachSigmas = 3.0;
// The core left out of the fit's window: 3 sigmas of the hardest blur (1.5 px, acceptance.md)
// and the edge fit's error beyond.
constexpr double kModelCoreMarginPx = 6.0;

// The scale s of a pixel relative to an ellipse: s^2 = a dx^2 + 2 b dx dy + c dy^2 (dx, dy
// from its centre), 1 on the ellipse, 0 at its centre, s on the ellipse scaled by s.
struct EllipseScale {
  Eigen::Vector2d centre;
  double a, b, c;

  explicit EllipseScale(const Ellipse& e) : centre(e.centre) {
    const double cs = std::cos(e.angle_rad), sn = std::sin(e.angle_rad);
    const double p = 1.0 / (e.semi_major * e.semi_major);
    const double q = 1.0 / (e.semi_minor * e.semi_minor);
    a = p * cs * cs + q * sn * sn;
    b = (p - q) * cs * sn;
    c = p * sn * sn + q * cs * cs;
  }
  // The pixels of row y within scale `s` of the centre, clipped to [lo, hi]: false when none.
  bool Span(int y, double s, int lo, int hi, int* x0, int* x1) const {
    const double dy = y - centre.y();
    const double disc = b * b * dy * dy - a * (c * dy * dy - s * s);
    if (!(disc >= 0.0)) return false;
    const double root = std::sqrt(disc);
    *x0 = std::max(lo, static_cast<int>(std::ceil(centre.x() + (-b * dy - root) / a)));
    *x1 = std::min(hi, static_cast<int>(std::floor(centre.x() + (-b * dy + root) / a)));
    return *x0 <= *x1;
  }
  double Squared(double dx, double dy) const {
    return a * dx * dx + 2.0 * b * dx * dy + c * dy * dy;
  }
};

// Two doubles, one SSE register: GCC's and clang's vector extension (as image_filters.cc's
// Float4).
using Double2 = double __attribute__((vector_size(16)));

// The pixels of a grey centroid's window: the ellipse scaled by `outer` about its centre.
struct Window {
  int x0, y0, x1, y1;  // inclusive
};

// The window's pixel box; nullopt when it leaves the image (a centroid of a cut window is
// pulled away from the border).
std::optional<Window> WindowIn(const ImageView8& image, const Ellipse& e, double outer) {
  const double reach = outer * e.semi_major + 1.0;
  const Window w{static_cast<int>(std::floor(e.centre.x() - reach)),
                 static_cast<int>(std::floor(e.centre.y() - reach)),
                 static_cast<int>(std::ceil(e.centre.x() + reach)),
                 static_cast<int>(std::ceil(e.centre.y() + reach))};
  if (!(w.x0 >= 0 && w.y0 >= 0 && w.x1 < image.width && w.y1 < image.height)) {
    return std::nullopt;
  }
  return w;
}

// Calls visit(dx, dy, s2, grey) for every pixel of window w within scale `outer` of the
// ellipse, row by row: dx, dy from its centre, s2 the pixel's squared scale.
template <typename Visit>
void ForEachPixelWithin(const ImageView8& image, const EllipseScale& scale, const Window& w,
                        double outer, Visit&& visit) {
  for (int y = w.y0; y <= w.y1; ++y) {
    int x0 = 0, x1 = 0;
    if (!scale.Span(y, outer, w.x0, w.x1, &x0, &x1)) continue;
    const std::uint8_t* row = image.Row(y);
    const double dy = y - scale.centre.y();
    for (int x = x0; x <= x1; ++x) {
      const double dx = x - scale.centre.x();
      visit(dx, dy, scale.Squared(dx, dy), row[x]);
    }
  }
}

// The print's and the page's grey around `e`: the page a plane a + b du + c dv (du, dv from
// e's centre) fitted to the ring between scales `inner` and `outer` (the light varies across
// a circle), the print the grey that nine tenths of the circle's core (scale 0.6) reach, so
// that texture in the print weighs nothing. nullopt when the ring or the core is too small
// to tell.
struct Levels {
  Eigen::Vector3d page;
  double print = 0.0;
  double noise = 0.0;  // the ring's RMS about its plane, grey levels
};
std::optional<Levels> MeasureLevels(const ImageView8& image, const Ellipse& e, const Window& w,
                                    double inner, double outer, bool light) {
  const EllipseScale scale(e);
  Eigen::Matrix3d normal = Eigen::Matrix3d::Zero();
  Eigen::Vector3d rhs = Eigen::Vector3d::Zero();
  std::array<int, 256> core{};  // the core's grey histogram
  double sum_sq = 0.0;          // the ring's squared grey levels
  int core_n = 0;
  ForEachPixelWithin(image, scale, w, outer,
                     [&](double dx, double dy, double s2, std::uint8_t level) {
                       if (s2 <= 0.36) {
                         ++core[level];
                         ++core_n;
                       } else if (s2 >= inner * inner) {
                         // The normal equations of (1, dx, dy): the upper triangle only (the
                         // lower one is its mirror, the same products), and the products with 1
                         // as the terms themselves.
                         const double grey = level;
                         normal(0, 0) += 1.0;
                         normal(0, 1) += dx;
                         normal(0, 2) += dy;
                         normal(1, 1) += dx * dx;
                         normal(1, 2) += dx * dy;
                         normal(2, 2) += dy * dy;
                         rhs += Eigen::Vector3d(grey, dx * grey, dy * grey);
                         sum_sq += grey * grey;
                       }
                     });
  normal(1, 0) = normal(0, 1);
  normal(2, 0) = normal(0, 2);
  normal(2, 1) = normal(1, 2);
  // A dozen ring pixels at least: three unknowns, and a ring of a circle 4 px across.
  if (core_n < 5 || normal(0, 0) < 12.0) return std::nullopt;
  const Eigen::LDLT<Eigen::Matrix3d> ldlt(normal);
  if (ldlt.info() != Eigen::Success || !ldlt.isPositive()) return std::nullopt;
  Levels levels;
  levels.page = ldlt.solve(rhs);
  // The residual sum of squares of a least-squares fit: sum g^2 - coefficients . rhs.
  levels.noise = std::sqrt(std::max(0.0, sum_sq - levels.page.dot(rhs)) / (normal(0, 0) - 3.0));
  // The grey nine tenths of the core reach: counted from the print's side.
  int seen = 0, grey = light ? 255 : 0;
  for (; seen + core[grey] < core_n - core_n / 10; grey += light ? -1 : 1) seen += core[grey];
  levels.print = grey;
  return levels;
}

// The centroid of the print's share of each pixel of the window (scale <= outer about e's
// centre): (page - grey) / (page - print), clamped to [0, 1]. nullopt when print and page
// are less than a grey level apart.
std::optional<Eigen::Vector2d> ShareCentroid(const ImageView8& image, const Ellipse& e,
                                             const Window& w, double outer, const Levels& levels) {
  const EllipseScale scale(e);
  double sum_w = 0.0;
  Eigen::Vector2d sum_wp = Eigen::Vector2d::Zero();
  std::vector<double> shares(static_cast<std::size_t>(w.x1 - w.x0 + 1));
  for (int y = w.y0; y <= w.y1; ++y) {
    int x0 = 0, x1 = 0;
    if (!scale.Span(y, outer, w.x0, w.x1, &x0, &x1)) continue;
    const std::uint8_t* row = image.Row(y);
    const double dy = y - e.centre.y();
    // The shares first, two pixels to a vector (two divisions to an instruction; each
    // lane's arithmetic is the scalar's, in the same order), then summed in order.
    const double cx = e.centre.x(), page_dy = levels.page[2] * dy;
    const Double2 zero = {0.0, 0.0}, one = {1.0, 1.0};
    bool steep = true;  // every |step| >= 1 so far
    int x = x0;
    for (; x + 1 <= x1; x += 2) {
      const Double2 at = {static_cast<double>(x), static_cast<double>(x + 1)};
      const Double2 page = (levels.page[0] + levels.page[1] * (at - cx)) + page_dy;
      const Double2 step = levels.print - page;
      const auto steep_pair = (step < zero ? -step : step) >= one;
      steep &= (steep_pair[0] != 0) & (steep_pair[1] != 0);
      const Double2 grey = {static_cast<double>(row[x]), static_cast<double>(row[x + 1])};
      const Double2 v = (grey - page) / step;
      const Double2 share = v < zero ? zero : (one < v ? one : v);  // std::clamp's order
      shares[x - x0] = share[0];
      shares[x + 1 - x0] = share[1];
    }
    bool flat = !steep;
    for (; x <= x1; ++x) {
      const double page = levels.page[0] + levels.page[1] * (x - cx) + page_dy;
      const double step = levels.print - page;
      flat |= !(std::abs(step) >= 1.0);
      shares[x - x0] = std::clamp((row[x] - page) / step, 0.0, 1.0);
    }
    if (flat) return std::nullopt;
    double row_w = 0.0, row_wx = 0.0;
    for (int x = x0; x <= x1; ++x) {
      const double share = shares[x - x0];
      row_w += share;
      row_wx += share * x;
    }
    sum_w += row_w;
    sum_wp += Eigen::Vector2d(row_wx, row_w * y);
  }
  if (!(sum_w > 0.0)) return std::nullopt;
  return sum_wp / sum_w;
}

// The window of the grey-level centres (GreyCentroid, ModelCentre) about an ellipse: its
// scale `outer` (the page ring from kBlurReachPx past the edge, where a blurred edge has
// reached the page, a further max(kRingPx, a quarter of the radius), in the semi-minor axis's
// pixels (along the major axis the ring is wider), as wide as the room leaves), its pixel
// box, and the levels of print and page. nullopt when the room leaves no ring, the window
// leaves the image, or the levels cannot be told.
struct GreyWindow {
  double outer;
  Window box;
  Levels levels;
};
std::optional<GreyWindow> GreyWindowOf(const ImageView8& image, const Ellipse& ellipse, bool light,
                                       double max_scale) {
  const double b = ellipse.semi_minor;
  const double inner = 1.0 + kCentroidBlurReachPx / b;
  const double ring_px =
      std::min(std::max(kCentroidRingPx, 0.25 * b), (max_scale - inner) * b - kNeighbourBlurPx);
  if (!(ring_px >= kCentroidMinRingPx)) return std::nullopt;
  const double outer = inner + ring_px / b;
  const std::optional<Window> w = WindowIn(image, ellipse, outer);
  if (!w) return std::nullopt;
  const std::optional<Levels> levels = MeasureLevels(image, ellipse, *w, inner, outer, light);
  if (!levels) return std::nullopt;
  return GreyWindow{outer, *w, *levels};
}

// ---- The model fit ------------------------------------------------------------------------

// The model's parameters: the ellipse's centre offset from the edge fit's (t), its conic
// Q (u^T Q u = 1 on the edge, u from the centre), the blur sigma, the page's illumination as a
// plane about the edge fit's centre, and the print's contrast k: grey = page (1 - k F), F
// the share of print that the blur leaves at the pixel.
enum ModelParam {
  // The geometry.
  kTx,
  kTy,
  kQa,
  kQb,
  kQc,
  kSigma,
  // The levels.
  kPage0,
  kPageU,
  kPageV,
  kContrast,
  kParams
};
constexpr int kGeometryParams = kPage0;
using ModelVector = Eigen::Matrix<double, kParams, 1>;
using ModelMatrix = Eigen::Matrix<double, kParams, kParams>;

// A window pixel, relative to the edge fit's centre.
struct ModelPixel {
  double du, dv, grey;
};

// The pixels of e's window w (within scale `outer` of it) but its core: those more than
// kModelCoreMarginPx inside the edge are all print at any blur the fit can meet, so they tell
// nothing of the geometry, only of the print's grey, which the edge's inner side tells too.
// A large circle's core is most of its window (a circle 55 px across: 40%).
std::vector<ModelPixel> WindowPixels(const ImageView8& image, const Ellipse& e, const Window& w,
                                     double outer) {
  const EllipseScale scale(e);
  const double core = std::max(0.0, 1.0 - kModelCoreMarginPx / e.semi_minor);
  std::vector<ModelPixel> pixels;
  ForEachPixelWithin(image, scale, w, outer,
                     [&](double dx, double dy, double s2, std::uint8_t grey) {
                       if (s2 >= core * core) pixels.push_back({dx, dy, static_cast<double>(grey)});
                     });
  return pixels;
}

// erfc(w) for w >= 0 given exp(-w^2), within 1.5e-7 (Abramowitz and Stegun 7.1.26): the
// model needs the Gaussian for its derivative anyway, and this spares a second transcendental
// per pixel; 1.5e-7 of the contrast is far below a grey level.
double ErfcFromGauss(double w, double gauss) {
  const double t = 1.0 / (1.0 + 0.3275911 * w);
  return t *
         (0.254829592 +
          t * (-0.284496736 + t * (1.421413741 + t * (-1.453152027 + t * 1.061405429)))) *
         gauss;
}

// The model's grey at pixel p and its derivatives by the levels and, for a pixel on the
// blurred edge (`edge`), by the geometry; elsewhere the pixel is all print or all page, and
// the geometry does not move its grey. The distance of p from the edge is the conic's
// first-order (Sampson) distance f / |grad f|, f = u^T Q u - 1, exact on the edge, monotonic
// along every ray from the centre and point-symmetric about it; the blurred edge's profile
// is the Gaussian's integral across it.
struct ModelGrey {
  double grey;
  bool edge;
  Eigen::Vector4d levels;                              // by kPage0 .. kContrast
  Eigen::Matrix<double, kGeometryParams, 1> geometry;  // by kTx .. kSigma, when `edge`
};
ModelGrey ModelGreyAt(const ModelVector& x, double inv_sigma, const ModelPixel& p) {
  const double ux = p.du - x[kTx], uy = p.dv - x[kTy];
  const double g0 = x[kQa] * ux + x[kQb] * uy, g1 = x[kQb] * ux + x[kQc] * uy;
  const double f = ux * g0 + uy * g1 - 1.0;
  const double inv_n = 1.0 / std::max(std::sqrt(g0 * g0 + g1 * g1), 1e-12);
  const double z = 0.5 * f * inv_n * inv_sigma;
  const double page = x[kPage0] + x[kPageU] * p.du + x[kPageV] * p.dv;
  ModelGrey m;
  m.edge = std::abs(z) < kModelEdgeReachSigmas;
  double share = z < 0.0 ? 1.0 : 0.0, pdf = 0.0;
  if (m.edge) {
    const double gauss = std::exp(-0.5 * z * z);
    pdf = gauss * (0.5 * std::numbers::inv_sqrtpi * std::numbers::sqrt2);
    const double tail = 0.5 * ErfcFromGauss(std::abs(z) * (0.5 * std::numbers::sqrt2), gauss);
    share = z < 0.0 ? 1.0 - tail : tail;
  }
  const double dim = 1.0 - x[kContrast] * share;
  m.grey = page * dim;
  m.levels << dim, dim * p.du, dim * p.dv, -page * share;
  if (!m.edge) return m;
  // d(grey)/d(distance), and the distance's derivatives.
  const double by_d = page * x[kContrast] * pdf * inv_sigma;
  const double qg0 = x[kQa] * g0 + x[kQb] * g1, qg1 = x[kQb] * g0 + x[kQc] * g1;
  const double c = 0.5 * f * inv_n * inv_n * inv_n;
  m.geometry << -by_d * (g0 * inv_n - c * qg0), -by_d * (g1 * inv_n - c * qg1),
      by_d * (0.5 * ux * ux * inv_n - c * g0 * ux),
      by_d * (ux * uy * inv_n - c * (g0 * uy + g1 * ux)),
      by_d * (0.5 * uy * uy * inv_n - c * g1 * uy), -by_d * z;
  return m;
}

// The upper triangle of *normal += j j^T over j's entries from kFirst on (j's others are 0):
// the lower triangle is its mirror, filled once for the solve.
template <int kFirst>
void AddOuterUpper(const ModelVector& j, ModelMatrix* normal) {
  for (int c = kFirst; c < kParams; ++c) {
    for (int r = kFirst; r <= c; ++r) (*normal)(r, c) += j[r] * j[c];
  }
}

// Sum of squared residuals at x, and the normal equations (J^T J, its upper triangle, and
// J^T r).
double ModelNormal(const std::vector<ModelPixel>& pixels, const ModelVector& x, ModelMatrix* normal,
                   ModelVector* rhs) {
  normal->setZero();
  rhs->setZero();
  double cost = 0.0;
  ModelVector j;
  const double inv_sigma = 1.0 / x[kSigma];
  for (const ModelPixel& p : pixels) {
    const ModelGrey m = ModelGreyAt(x, inv_sigma, p);
    const double r = p.grey - m.grey;
    cost += r * r;
    if (m.edge) {
      j << m.geometry, m.levels;
      AddOuterUpper<0>(j, normal);
      *rhs += r * j;
    } else {
      // Most of the window: only the levels' block.
      j.tail<4>() = m.levels;
      AddOuterUpper<kPage0>(j, normal);
      rhs->tail<4>() += r * m.levels;
    }
  }
  return cost;
}

// Levenberg-Marquardt from *x (Marquardt's scaling: the parameters' units differ by orders
// of magnitude): true when it converged, the centre's last step under the tolerance.
bool FitModel(const std::vector<ModelPixel>& pixels, ModelVector* x) {
  ModelMatrix normal;
  ModelVector rhs;
  double cost = ModelNormal(pixels, *x, &normal, &rhs);
  double lambda = kModelStartDamping;
  bool converged = false;
  for (int iteration = 0; iteration < kModelMaxIterations && !converged; ++iteration) {
    ModelMatrix damped = normal.selfadjointView<Eigen::Upper>();
    damped.diagonal() *= 1.0 + lambda;
    const ModelVector step = damped.ldlt().solve(rhs);
    const ModelVector next = *x + step;
    ModelMatrix next_normal;
    ModelVector next_rhs;
    // A blur of 0 or less is no image: such a step is refused as a worse one.
    const double next_cost = next[kSigma] > 0.0 ? ModelNormal(pixels, next, &next_normal, &next_rhs)
                                                : std::numeric_limits<double>::infinity();
    if (next_cost < cost) {
      *x = next;
      cost = next_cost;
      normal = next_normal;
      rhs = next_rhs;
      lambda *= 0.1;
      converged = step.head<2>().norm() < kModelCentreTolerancePx;
    } else {
      lambda *= 10.0;
      if (lambda > kModelMaxDamping) return false;
    }
  }
  return converged;
}

// The grey centroid of window g (GreyCentroid's contract).
std::optional<Eigen::Vector2d> CentroidIn(const ImageView8& image, const Ellipse& ellipse,
                                          const GreyWindow& g) {
  const std::optional<Eigen::Vector2d> c = ShareCentroid(image, ellipse, g.box, g.outer, g.levels);
  if (!c || (*c - ellipse.centre).norm() > 0.25 * ellipse.semi_minor) return std::nullopt;
  return c;
}

// The model fit in window g (ModelCentre's contract): nullopt where the page is too quiet for
// it or the fit fails.
std::optional<Eigen::Vector2d> ModelFitIn(const ImageView8& image, const Ellipse& ellipse,
                                          bool light, const GreyWindow& g) {
  if (!(std::abs(g.levels.page[0]) >= 1.0) || g.levels.noise < kModelMinNoise) return std::nullopt;
  const std::vector<ModelPixel> pixels = WindowPixels(image, ellipse, g.box, g.outer);
  const EllipseScale scale(ellipse);
  ModelVector x;
  x << 0.0, 0.0, scale.a, scale.b, scale.c, kModelStartSigmaPx, g.levels.page[0], g.levels.page[1],
      g.levels.page[2], 1.0 - g.levels.print / g.levels.page[0];
  const bool converged = FitModel(pixels, &x);
  const double b = ellipse.semi_minor;
  const double contrast = x[kContrast] * x[kPage0];
  if (!converged || !(x[kSigma] < 0.5 * b) || !(light ? contrast <= -1.0 : contrast >= 1.0) ||
      !(x.head<2>().norm() <= 0.25 * b)) {
    return std::nullopt;
  }
  return ellipse.centre + x.head<2>();
}

}  // namespace

std::optional<Eigen::Vector2d> ModelCentre(const ImageView8& image, const Ellipse& ellipse,
                                           bool light, double max_scale) {
  const std::optional<GreyWindow> g = GreyWindowOf(image, ellipse, light, max_scale);
  if (!g) return std::nullopt;
  if (const std::optional<Eigen::Vector2d> c = ModelFitIn(image, ellipse, light, *g)) return c;
  return CentroidIn(image, ellipse, *g);
}

std::optional<Eigen::Vector2d> GreyCentroid(const ImageView8& image, const Ellipse& ellipse,
                                            bool light, double max_scale) {
  const std::optional<GreyWindow> g = GreyWindowOf(image, ellipse, light, max_scale);
  if (!g) return std::nullopt;
  return CentroidIn(image, ellipse, *g);
}

CircleEdgeFitter::CircleEdgeFitter(int rays) {
  // Evenly spaced: the seeding pass uses every other one (it only has to bring the edge
  // windows onto the edge).
  for (int k = 0; k < rays; ++k) {
    const double theta = 2.0 * std::numbers::pi * k / rays;
    fine_.emplace_back(std::cos(theta), std::sin(theta));
    if (k % 2 == 0) coarse_.push_back(fine_.back());
  }
}

std::optional<Ellipse> CircleEdgeFitter::Measure(const ImageView8& image, const Ellipse& seed,
                                                 bool light, int min_contrast,
                                                 EdgeShape* shape) const {
  const Patch patch = MakePatch(image, seed);
  // First pass: 0.35 of the radius covers the seed's error (a blob's threshold edge, or a
  // prediction within half a radius) while it stays short of the nearest other edge of the
  // boards (the circle board's white bar, 0.4 radius from the circles next to it); 8 samples
  // a side locate the edge to a fraction of a pixel.
  const std::optional<Ellipse> first =
      FitCircleEdge(patch, seed, light, coarse_, {0.35, 0.0, 8}, min_contrast);
  if (!first) return std::nullopt;
  // Second pass: centred on the first fit, every 0.5 px over +-3 px, which holds an edge
  // blurred by sigma 1.5 and the first pass's error.
  std::optional<Ellipse> second =
      FitCircleEdge(patch, *first, light, fine_, {0.35, 3.0, 0}, min_contrast, shape);
  if (!second) return std::nullopt;
  const double r_seed = std::sqrt(seed.semi_major * seed.semi_minor);
  const double r_meas = std::sqrt(second->semi_major * second->semi_minor);
  // Blur moves the edge by a fraction of its sigma; a third of the radius or more means
  // another edge was measured.
  if ((second->centre - seed.centre).norm() > 0.5 * r_seed ||
      std::abs(r_meas - r_seed) > 0.33 * r_seed + 1.0) {
    return std::nullopt;
  }
  return second;
}

}  // namespace linecal
