#include "detectors/markers/page_edge_fit.h"

#include <Eigen/Cholesky>
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <optional>
#include <span>
#include <vector>

#include "detectors/common/edge_lines.h"
#include "detectors/common/homography.h"

namespace linecal {
namespace {

// Profile samples along the normal, px: one per pixel's width (every half pixel gained 0.002
// px RMS on the evaluation for 10% more time).
constexpr double kSampleStepPx = 1.0;
// The paint along a ray is read every kPaintStepPx (a printed shape narrower than that is
// lost to the blur anyway) and each change bisected to kPaintTolerancePx: far finer than the
// fit's precision.
constexpr double kPaintStepPx = 1.0;
constexpr double kPaintTolerancePx = 4e-3;
// Blur (sigma, px) the fit accepts: the render's sharpest (0.5 px plus the pixel) to well
// past the test set's 1.5 px.
constexpr double kMinSigmaPx = 0.3;
constexpr double kMaxSigmaPx = 3.0;
// Dark intervals are read this many largest sigmas beyond the samples: the rest of the
// normal CDF is under 1e-3.
constexpr double kReachSigmas = 3.0;
// Samples reach this many blur sigmas past the side's edge and past the border's inner edge
// (no farther than a cell outside and two inside): beyond it the profile holds nothing of
// the side, and the page is less one-dimensional (neighbouring cells along the side).
constexpr double kRangeSigmas = 3.0;
// The blur assumed for the first pass's sample range; the second uses the first's fit.
constexpr double kFirstSigmaPx = 1.2;
// Profiles per side: four points fix a line and average noise; more than 32 add little.
constexpr int kMinProfilesPerSide = 4;
constexpr int kMaxProfilesPerSide = 32;
// Levenberg-Marquardt iterations: 3-6 from the edge-point corners, 13 at most seen.
constexpr int kMaxIterations = 20;

// The normal CDF and density, tabulated: the fit evaluates them some 10^5 times per marker,
// and std::erfc and std::exp were most of its time. Linear interpolation on steps of 1/64
// is within 1e-5 of both; beyond 8 sigmas they are 0 or 1.
constexpr double kTableStep = 1.0 / 64.0;
constexpr double kTableReach = 8.0;
constexpr int kTableSize = static_cast<int>(2.0 * kTableReach / kTableStep) + 2;

struct NormalTable {
  std::array<double, kTableSize> cdf;
  std::array<double, kTableSize> pdf;
  NormalTable() {
    for (int i = 0; i < kTableSize; ++i) {
      const double z = -kTableReach + i * kTableStep;
      cdf[i] = 0.5 * std::erfc(-z * M_SQRT1_2);
      pdf[i] = 0.3989422804014327 * std::exp(-0.5 * z * z);
    }
  }
};

const NormalTable& Table() {
  static const NormalTable table;
  return table;
}

double Interpolate(const std::array<double, kTableSize>& t, double z, double below, double above) {
  if (!(z > -kTableReach)) return below;
  if (!(z < kTableReach)) return above;
  const double x = (z + kTableReach) / kTableStep;
  const int i = static_cast<int>(x);
  const double f = x - i;
  return t[i] + f * (t[i + 1] - t[i]);
}

double NormalCdf(double z) { return Interpolate(Table().cdf, z, 0.0, 1.0); }
double NormalPdf(double z) { return Interpolate(Table().pdf, z, 0.0, 0.0); }

struct Interval {
  double a = 0.0;  // px along the outward normal, a < b
  double b = 0.0;
};

// The page's darkness along a profile as steps: at s it is base plus the c of every step
// with x > s (c = darkness just inside x minus just outside it, s growing outward). Blurred
// and moved outward by the fit's shift, base + sum of c Phi((x + shift - s) / sigma)
// (Evaluate). The steps of a profile's three rays that fall together are merged, so a page
// that is the same along them costs no more than one ray.
struct Step {
  double x = 0.0;  // px along the outward normal
  double c = 0.0;  // darkness just below x minus just above it
};

struct Profile {
  double u = 0.0;                                    // px along the side from its middle
  Eigen::Vector2d origin = Eigen::Vector2d::Zero();  // on the side, image px
  std::vector<double> s;                             // sample positions along the normal, px
  std::vector<double> grey;                          // bilinear grey levels there
  double base = 0.0;                                 // darkness outside the last step
  std::vector<Step> steps;
};

enum class Shade { kLight, kDark, kUnknown };

Shade ShadeAt(const Board& board, const Eigen::Matrix3d& H_board_image, const Eigen::Vector2d& uv) {
  const Eigen::Vector2d p = ApplyHomography(H_board_image, uv);
  switch (board.PaintAt(p)) {
    case Paint::kWhite:
      return Shade::kLight;
    case Paint::kBlack:
      return Shade::kDark;
    default:
      return Shade::kUnknown;
  }
}

// What the page prints along origin + s n, s in [lo, hi]: its dark intervals, and the
// nearest points on either side of s = 0 (the side's edge) where it is unknown (a hole, off
// the page: what shows there is not printed), +-infinity when there are none. Unknown paint
// counts as dark in the intervals; the samples stay clear of it (FitOnce).
struct RayPaint {
  std::vector<Interval> dark;
  double unknown_below = -std::numeric_limits<double>::infinity();
  double unknown_above = std::numeric_limits<double>::infinity();
};

RayPaint PaintAlong(const Board& board, const Eigen::Matrix3d& H_board_image,
                    const Eigen::Vector2d& origin, const Eigen::Vector2d& n, double lo, double hi) {
  RayPaint ray;
  const auto dark_at = [&](double s) {
    const Shade shade = ShadeAt(board, H_board_image, origin + s * n);
    if (shade == Shade::kUnknown) {
      if (s < 0.0) ray.unknown_below = std::max(ray.unknown_below, s);
      if (s >= 0.0) ray.unknown_above = std::min(ray.unknown_above, s);
    }
    return shade != Shade::kLight;
  };
  bool was_dark = dark_at(lo);
  double start = lo;
  for (double s = lo + kPaintStepPx;; s += kPaintStepPx) {
    const double here = std::min(s, hi);
    const bool is_dark = dark_at(here);
    if (is_dark != was_dark) {
      // Bisect the change between here - step and here.
      double x0 = here - kPaintStepPx;
      double x1 = here;
      while (x1 - x0 > kPaintTolerancePx) {
        const double mid = 0.5 * (x0 + x1);
        (dark_at(mid) == was_dark ? x0 : x1) = mid;
      }
      const double edge = 0.5 * (x0 + x1);
      if (was_dark) ray.dark.push_back({start, edge});
      start = edge;
      was_dark = is_dark;
    }
    if (here >= hi) break;
  }
  if (was_dark) ray.dark.push_back({start, hi});
  return ray;
}

// Adds the dark intervals of one ray, of quadrature weight w, to p's steps. An interval
// that reaches an end of the ray (lo or hi) is taken to go on past it: the step there is
// dropped (at lo) or folded into the base (at hi).
void AddRay(const std::vector<Interval>& dark, double w, double lo, double hi, Profile* p) {
  for (const Interval& iv : dark) {
    if (iv.a > lo) p->steps.push_back({iv.a, -w});
    if (iv.b < hi) {
      p->steps.push_back({iv.b, w});
    } else {
      p->base += w;
    }
  }
}

// Sorts p's steps and merges those within a bisection tolerance of each other (the same
// printed edge seen by several rays).
void MergeSteps(Profile* p) {
  std::sort(p->steps.begin(), p->steps.end(),
            [](const Step& a, const Step& b) { return a.x < b.x; });
  std::vector<Step> merged;
  for (const Step& st : p->steps) {
    if (!merged.empty() && st.x - merged.back().x < 2.0 * kPaintTolerancePx) {
      merged.back().c += st.c;
    } else {
      merged.push_back(st);
    }
  }
  merged.erase(std::remove_if(merged.begin(), merged.end(),
                              [](const Step& st) { return std::abs(st.c) < 1e-9; }),
               merged.end());
  p->steps = std::move(merged);
}

// Fitted parameters of one side: x = (delta, theta, sigma, L, D).
using Params = Eigen::Matrix<double, 5, 1>;

// Residuals (observed - model) and, when J is not null, the model's derivatives. Returns the
// sum of squared residuals.
double Evaluate(std::span<const Profile> profiles, const Params& x,
                Eigen::Matrix<double, 5, 5>* JtJ, Params* Jtr) {
  const double delta = x(0);
  const double theta = x(1);
  const double sigma = x(2);
  const double light = x(3);
  const double dark_level = x(4);
  if (JtJ != nullptr) {
    JtJ->setZero();
    Jtr->setZero();
  }
  double cost = 0.0;
  for (const Profile& p : profiles) {
    const double shift = delta + theta * p.u;
    for (std::size_t i = 0; i < p.s.size(); ++i) {
      double darkness = p.base;
      double d_shift = 0.0;
      double d_sigma = 0.0;
      for (const Step& st : p.steps) {
        // Darkness c below x: c Phi((x + shift - s) / sigma).
        const double z = (st.x + shift - p.s[i]) / sigma;
        darkness += st.c * NormalCdf(z);
        if (JtJ != nullptr) {
          const double pz = st.c * NormalPdf(z);
          d_shift += pz / sigma;
          d_sigma -= z * pz / sigma;
        }
      }
      const double model = light + (dark_level - light) * darkness;
      const double r = p.grey[i] - model;
      cost += r * r;
      if (JtJ != nullptr) {
        const double contrast = dark_level - light;
        Params j;
        j << contrast * d_shift, contrast * d_shift * p.u, contrast * d_sigma, 1.0 - darkness,
            darkness;
        *JtJ += j * j.transpose();
        *Jtr += j * r;
      }
    }
  }
  return cost;
}

// Levenberg-Marquardt from delta = theta = 0, sigma = sigma_start, and the light and dark levels
// that fit best at those. nullopt when the fit leaves the plausible range.
std::optional<Params> FitSide(std::span<const Profile> profiles, double sigma_start,
                              double max_shift_px, double min_contrast) {
  Params x;
  x << 0.0, 0.0, sigma_start, 0.0, 0.0;
  {
    // At fixed geometry the model is linear in L and D.
    Eigen::Matrix2d A = Eigen::Matrix2d::Zero();
    Eigen::Vector2d b = Eigen::Vector2d::Zero();
    for (const Profile& p : profiles) {
      for (std::size_t i = 0; i < p.s.size(); ++i) {
        double darkness = p.base;
        for (const Step& st : p.steps) darkness += st.c * NormalCdf((st.x - p.s[i]) / x(2));
        const Eigen::Vector2d row(1.0 - darkness, darkness);
        A += row * row.transpose();
        b += row * p.grey[i];
      }
    }
    const Eigen::LDLT<Eigen::Matrix2d> solve(A);
    if (solve.info() != Eigen::Success || !solve.isPositive()) return std::nullopt;
    x.tail<2>() = solve.solve(b);
  }
  double lambda = 1e-3;
  Eigen::Matrix<double, 5, 5> JtJ;
  Params Jtr;
  double cost = Evaluate(profiles, x, &JtJ, &Jtr);
  for (int iteration = 0; iteration < kMaxIterations; ++iteration) {
    Eigen::Matrix<double, 5, 5> damped = JtJ;
    damped.diagonal() += lambda * JtJ.diagonal().cwiseMax(1e-12);
    const Eigen::LDLT<Eigen::Matrix<double, 5, 5>> solve(damped);
    if (solve.info() != Eigen::Success) return std::nullopt;
    const Params step = solve.solve(Jtr);
    Params trial = x + step;
    trial(2) = std::clamp(trial(2), 0.5 * kMinSigmaPx, 2.0 * kMaxSigmaPx);
    Eigen::Matrix<double, 5, 5> JtJ_trial;
    Params Jtr_trial;
    const double trial_cost = Evaluate(profiles, trial, &JtJ_trial, &Jtr_trial);
    if (trial_cost < cost) {
      const bool converged = std::abs(step(0)) < 1e-4 && std::abs(step(2)) < 1e-3;
      x = trial;
      cost = trial_cost;
      JtJ = JtJ_trial;
      Jtr = Jtr_trial;
      lambda = std::max(lambda * 0.3, 1e-7);
      if (converged) break;
    } else {
      lambda *= 10.0;
      if (lambda > 1e6) break;  // no step lowers the cost: at the minimum
    }
  }
  if (!(x(2) >= kMinSigmaPx && x(2) <= kMaxSigmaPx)) return std::nullopt;
  if (!(x(3) - x(4) >= min_contrast)) return std::nullopt;
  if (!(std::abs(x(0)) <= max_shift_px)) return std::nullopt;
  return x;
}

// One pass: every side fitted on the page drawn through the current corners.
bool FitOnce(const ImageView8& image, const Board& board, int cells,
             const std::array<Eigen::Vector2d, 4>& corners_board, double min_contrast, int stride,
             double* sigma_hint_io, std::array<Eigen::Vector2d, 4>* corners_px) {
  const double sigma_hint = *sigma_hint_io;
  double sigma_sum = 0.0;
  const std::array<Eigen::Vector2d, 4>& c = *corners_px;
  HomographyFitOptions exact;
  exact.refine = false;  // four points: the DLT is exact
  const std::optional<HomographyFit> fit = FitHomography(
      std::span<const Eigen::Vector2d>(corners_board), std::span<const Eigen::Vector2d>(c), exact);
  if (!fit.has_value()) return false;
  const Eigen::Matrix3d H_board_image = fit->H.inverse();
  const Eigen::Vector2d centre = 0.25 * (c[0] + c[1] + c[2] + c[3]);
  std::array<Line2d, 4> lines;
  double cell_px_min = 1e9;
  for (int k = 0; k < 4; ++k) {
    const Eigen::Vector2d a = c[k];
    const Eigen::Vector2d b = c[(k + 1) % 4];
    const double len = (b - a).norm();
    if (!(len >= 2.0)) return false;
    const Eigen::Vector2d d = (b - a) / len;
    Eigen::Vector2d n(d.y(), -d.x());
    if (n.dot(0.5 * (a + b) - centre) < 0.0) n = -n;
    const double cell_px =
        0.5 * ((c[(k + 2) % 4] - b).norm() + (a - c[(k + 3) % 4]).norm()) / cells;
    cell_px_min = std::min(cell_px_min, cell_px);
    const double lo = -std::min(
        {2.0 * cell_px, cell_px + kRangeSigmas * sigma_hint, 2.0 * kRangeSigmas * sigma_hint});
    const double hi = std::min(cell_px, kRangeSigmas * sigma_hint);
    // Twice the blur expected: the fit may find it larger.
    const double reach = kReachSigmas * std::min(kMaxSigmaPx, 2.0 * sigma_hint);
    // Along the side, between its corner cells: the corners' two-dimensional blur is not
    // in a profile's model.
    const double t0 = 1.0 / cells;
    const double t1 = 1.0 - t0;
    const int count = static_cast<int>(std::clamp((t1 - t0) * len / stride,
                                                  static_cast<double>(kMinProfilesPerSide),
                                                  static_cast<double>(kMaxProfilesPerSide)));
    std::vector<Profile> profiles;
    profiles.reserve(count);
    for (int i = 0; i < count; ++i) {
      const double t = t0 + (t1 - t0) * (i + 0.5) / count;
      Profile p;
      p.origin = a + t * (b - a);
      p.u = (t - 0.5) * len;
      // The blur along the side, by three-point Gauss-Hermite quadrature: rays sqrt(3)
      // sigma to either side weigh 1/6 each, the profile's own 2/3. Where the page is the
      // same along all three (the middle of a run of like cells), one ray stands for them.
      // The samples keep two sigmas from unknown paint (the round-hole board's holes lie
      // 1.4 cells beyond its markers).
      double lo_p = lo;
      double hi_p = hi;
      for (int r = 0; r < 3; ++r) {
        const Eigen::Vector2d o = p.origin + (r - 1) * std::sqrt(3.0) * sigma_hint * d;
        const RayPaint ray = PaintAlong(board, H_board_image, o, n, lo - reach, hi + reach);
        AddRay(ray.dark, r == 1 ? 2.0 / 3.0 : 1.0 / 6.0, lo - reach, hi + reach, &p);
        lo_p = std::max(lo_p, ray.unknown_below + 2.0 * sigma_hint);
        hi_p = std::min(hi_p, ray.unknown_above - 2.0 * sigma_hint);
      }
      // The profile must still hold the edge's blur on both sides.
      if (lo_p > -sigma_hint || hi_p < sigma_hint) continue;
      if (!InsideForBilinearGrey(image, p.origin + lo_p * n) ||
          !InsideForBilinearGrey(image, p.origin + hi_p * n)) {
        continue;
      }
      MergeSteps(&p);
      for (double s = lo_p; s <= hi_p + 1e-9; s += kSampleStepPx) {
        const Eigen::Vector2d q = p.origin + s * n;
        p.s.push_back(s);
        p.grey.push_back(BilinearGrey(image, q.x(), q.y()));
      }
      profiles.push_back(std::move(p));
    }
    if (static_cast<int>(profiles.size()) < kMinProfilesPerSide) return false;
    const std::optional<Params> x = FitSide(profiles, sigma_hint, 0.5 * cell_px, min_contrast);
    if (!x.has_value()) return false;
    sigma_sum += (*x)(2);
    // The side moved by delta + theta u: the line through its moved middle, turned by theta.
    const Eigen::Vector2d mid = 0.5 * (a + b) + (*x)(0) * n;
    lines[k] = Line2d{mid, (d + (*x)(1) * n).normalized()};
  }
  std::array<Eigen::Vector2d, 4> out;
  for (int k = 0; k < 4; ++k) {
    // Corner k starts side k and ends side k - 1.
    const std::optional<Eigen::Vector2d> corner = IntersectLines(lines[(k + 3) % 4], lines[k]);
    if (!corner.has_value()) return false;
    if ((*corner - c[k]).norm() > 0.5 * cell_px_min) return false;
    out[k] = *corner;
  }
  *corners_px = out;
  *sigma_hint_io = 0.25 * sigma_sum;
  return true;
}

}  // namespace

bool FitMarkerSidesToPage(const ImageView8& image, const Board& board, int cells,
                          const std::array<Eigen::Vector2d, 4>& corners_board, double min_contrast,
                          std::array<Eigen::Vector2d, 4>* corners_px) {
  std::array<Eigen::Vector2d, 4> corners = *corners_px;
  double sigma = kFirstSigmaPx;
  // The first pass, on every third profile, finds the blur and takes out most of the
  // corners' error; the second, on all, is the fit reported.
  for (const int stride : {3, 1}) {
    if (!FitOnce(image, board, cells, corners_board, min_contrast, stride, &sigma, &corners)) {
      return false;
    }
  }
  // Three quarters of a cell in all: a start up to half a cell off (dark print within a cell
  // of the border pulls the edge points) plus what the fit may rightly move beyond it.
  for (int k = 0; k < 4; ++k) {
    if ((corners[k] - (*corners_px)[k]).norm() >
        0.75 * ((*corners_px)[(k + 1) % 4] - (*corners_px)[k]).norm() / cells) {
      return false;
    }
  }
  *corners_px = corners;
  return true;
}

}  // namespace linecal
