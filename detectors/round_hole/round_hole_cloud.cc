#include "detectors/round_hole/round_hole_cloud.h"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <array>
#include <cmath>
#include <complex>
#include <cstddef>
#include <limits>
#include <map>
#include <numbers>
#include <set>

namespace linecal {
namespace {

// Tukey biweight cut-off in robust sigmas: 95% efficiency under Gaussian noise.
constexpr double kTukeyC = 4.685;
// Median absolute deviation to sigma for Gaussian noise.
constexpr double kMadToSigma = 1.4826;
// The plane fit's robust sigma never goes below 2 mm: the sensors' distance unit (2-4 mm)
// rounds ranges that coarsely even without noise.
constexpr double kMinPlaneSigmaM = 0.002;
// A plane whose robust sigma exceeds 6 cm (twice the largest range noise of docs/acceptance.md)
// is clutter, not a board.
constexpr double kMaxPlaneSigmaM = 0.06;
// Fewer points than this on the plane cannot hold a board (a 16-ring LiDAR at 8 m puts about
// 150 points per rotation on it).
constexpr int kMinPlanePoints = 20;
// Iteration caps: the plane fit and the edge fit converge in well under ten iterations from
// the prior; these only bound the cost on bad data.
constexpr int kPlaneIterations = 30;
constexpr int kEdgeIterations = 30;
// Two consecutive returns of a ring farther apart than this many azimuth steps have a gap
// between them (a hole, or the page's end): between one step (paper) and two (one ray lost).
constexpr double kGapSteps = 1.5;
// Virtual rays beyond each end of a ring's points, for the coarse search: three steps tell
// "the page ends here" without reaching into the next board.
constexpr int kEndSamples = 3;
// Virtual rays per gap: the region is under 2 m wide and a ring's step over 5 mm for the
// supported models at 3 m, so more than 400 means a bad azimuth, not a longer gap.
constexpr int kMaxGapSamples = 400;
// The coarse search uses at most this many samples (points and virtual rays): enough to
// cover every ring of a Pandar64 at 3 m, and it bounds the search to about 2 * 10^6 look-ups.
constexpr std::size_t kMaxSamples = 2000;
// Coarse search grid: 2 cm shifts (a tenth of a hole, within the edge fit's reach) and
// 0.5 degree rotations (at the page's corner, 0.78 m away, 7 mm).
constexpr double kShiftStepM = 0.02;
constexpr double kRotationStepRad = 0.5 * std::numbers::pi / 180.0;
// The edge fit's first gate: residuals beyond 6 cm (the coarse grid's error plus a 8 m ring's
// azimuth step) are wrong associations; later gates follow the edges' robust sigma, never
// below 1 cm (so quantisation never shrinks it below the azimuth step of a ring at 3 m).
constexpr double kInitialEdgeGateM = 0.06;
constexpr double kMinEdgeGateM = 0.01;
// Fewer edges than this cannot fix three in-plane parameters robustly.
constexpr int kMinEdges = 6;
// Edges of a fitted board scatter by the azimuth step (at most about 3 cm at 8 m for 0.2
// degrees); an RMS beyond 5 cm means the model does not fit.
constexpr double kMaxEdgeRmsM = 0.05;
// A return this far (metres) in front of the expected plane, whose ray meets the region, is an
// occluder: beyond the plane fit's reach (its cut-off stays under 0.28 m only for wild data;
// for range noise of 1-3 cm it is under 0.15 m) and nearer than any hole's background.
constexpr double kOccluderDepthM = 0.15;
// With this many rings through the holes or fewer, the board's y gets the profile variance
// (ProfileYVariance); more rings at more heights keep the fit linear.
constexpr int kFewRingsThroughHoles = 4;
// See the edge extraction: rings spanning less of the page than this are dropped.
constexpr double kMinRingSpanPages = 0.1;
// Edge errors beyond the azimuth quantisation and the plane's error (the points' float and
// packet rounding, well under a millimetre): 0.3 mm, as a variance in m^2. 1 mm had made the
// VLP-16 boards' x 6% too uncertain (a step is 1 cm on them, variance 8 mm^2).
constexpr double kEdgeFloorVarM2 = 1e-7;
// An edge whose ring runs along its boundary this closely (the step seen through the
// boundary's normal, metres) cannot say where along the ring the boundary is.
constexpr double kMinAlongM = 1e-6;
// Convergence of both fits: updates below 1e-7 (relative, m or rad) change nothing measurable.
constexpr double kConvergence = 1e-7;

struct RoiPoint {
  Eigen::Vector3d p_lidar;
  int ring = 0;
  int frame = 0;
};

// A ring edge: where the ring leaves or enters paper, in plane coordinates. Edges of one gap
// share `gap` (-1 for the two ends of a ring's points).
struct Edge {
  Eigen::Vector2d p_plane;
  int group = 0;
  int gap = -1;
  // One azimuth step of the ring at the edge, in the plane: the edge lies somewhere within
  // half of it of p_plane (uniformly), the error the in-plane covariance is built from.
  Eigen::Vector2d step_plane = Eigen::Vector2d::Zero();
  // Where along the ring, in azimuth steps from the ring's first point: the edges of one ring
  // share its firing phase, so their errors are correlated as sawtooth functions this far
  // apart.
  double steps_along = 0.0;
};

// A sample of the coarse search: a return on the plane (paper = true) or a virtual ray that
// passed through it (paper = false).
struct Sample {
  Eigen::Vector2d p_plane;
  bool paper = true;
};

struct Circle {
  Eigen::Vector2d centre_board;
  double radius_m = 0.0;
  int id = 0;
};

// The drawing as paper / not paper on a grid of kRasterM over the page, for the coarse
// search's million look-ups (Board::PaintAt walks the shapes each time). A 5 mm grid is a
// quarter of the search's 2 cm step; the fine fit uses the exact circles and outline.
constexpr double kRasterM = 0.005;
class PaperRaster {
 public:
  explicit PaperRaster(const Board& board)
      : half_(0.5 * board.page_size_m()),
        nx_(static_cast<int>(std::ceil(board.page_size_m().x() / kRasterM))),
        ny_(static_cast<int>(std::ceil(board.page_size_m().y() / kRasterM))),
        paper_(static_cast<std::size_t>(nx_) * ny_) {
    for (int iy = 0; iy < ny_; ++iy) {
      for (int ix = 0; ix < nx_; ++ix) {
        const Paint paint = board.PaintAt(
            Eigen::Vector2d((ix + 0.5) * kRasterM - half_.x(), (iy + 0.5) * kRasterM - half_.y()));
        paper_[static_cast<std::size_t>(iy) * nx_ + ix] =
            paint == Paint::kWhite || paint == Paint::kBlack;
      }
    }
  }
  bool PaperAt(const Eigen::Vector2d& m_board) const {
    const double fx = (m_board.x() + half_.x()) / kRasterM;
    const double fy = (m_board.y() + half_.y()) / kRasterM;
    if (!(fx >= 0.0 && fy >= 0.0 && fx < nx_ && fy < ny_)) return false;
    return paper_[static_cast<std::size_t>(fy) * nx_ + static_cast<std::size_t>(fx)];
  }

 private:
  Eigen::Vector2d half_;
  int nx_ = 0;
  int ny_ = 0;
  std::vector<bool> paper_;
};

double Median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  const auto mid = v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2);
  std::nth_element(v.begin(), mid, v.end());
  return *mid;
}

Eigen::Matrix2d Rotation2(double theta) { return Eigen::Rotation2Dd(theta).toRotationMatrix(); }

// The signed distance of m_board to the nearest boundary of the model (a hole circle or a
// side of the page, each taken as a whole line), its outward unit gradient, and which it is
// (a hole index, or -1 - s for the page's side s: +x, -x, +y, -y).
double NearestBoundary(const std::vector<Circle>& holes, const Eigen::Vector2d& half_page,
                       const Eigen::Vector2d& m_board, Eigen::Vector2d* gradient, int* which) {
  const std::array<double, 4> sides = {m_board.x() - half_page.x(), -half_page.x() - m_board.x(),
                                       m_board.y() - half_page.y(), -half_page.y() - m_board.y()};
  const std::array<Eigen::Vector2d, 4> normals = {Eigen::Vector2d(1, 0), Eigen::Vector2d(-1, 0),
                                                  Eigen::Vector2d(0, 1), Eigen::Vector2d(0, -1)};
  double best = std::numeric_limits<double>::infinity();
  for (int s = 0; s < 4; ++s) {
    if (std::abs(sides[s]) < std::abs(best)) {
      best = sides[s];
      *gradient = normals[s];
      *which = -1 - s;
    }
  }
  for (std::size_t i = 0; i < holes.size(); ++i) {
    const Eigen::Vector2d v = m_board - holes[i].centre_board;
    const double len = v.norm();
    const double d = len - holes[i].radius_m;
    if (std::abs(d) < std::abs(best) && len > 0.0) {
      best = d;
      *gradient = v / len;
      *which = static_cast<int>(i);
    }
  }
  return best;
}

struct PlaneFit {
  Eigen::Vector3d n_lidar;
  double d_m = 0.0;       // n . p = d on the plane
  double cutoff_m = 0.0;  // the final Tukey cut-off, on range residuals
  // 1-sigma of the normal's tilt along its worse axis, radians, from the fit's covariance.
  double normal_sigma_rad = 0.0;
  Eigen::Matrix3d cov_w = Eigen::Matrix3d::Zero();  // of w = n / d, sigma^2 H^-1
  bool ok = false;
};

// The range residual of p_lidar against the plane w . p = 1 (w = n / d): measured range minus
// the range at which its ray meets the plane. Infinite for a ray parallel to the plane.
double RangeResidual(const Eigen::Vector3d& w, const Eigen::Vector3d& p_lidar) {
  const double range = p_lidar.norm();
  const double wu = w.dot(p_lidar) / range;
  return wu > 0.0 ? range - 1.0 / wu : std::numeric_limits<double>::infinity();
}

// Tukey IRLS plane fit from the expected plane (normal n0, offset from the points' median),
// on range residuals: LiDAR noise is along the rays (whose directions are exact), and an
// orthogonal (PCA) fit of such points, like any fit with the noisy points as regressors,
// tilts the normal towards the rays by about sigma^2 sin(2 incidence) / (2 spread^2): 0.3
// degree for a 35 degree incidence at 3 cm. Gauss-Newton in w = n / d, one step per
// reweighting; the predicted range of a ray u is 1 / (w . u).
PlaneFit FitPlane(const std::vector<RoiPoint>& points, const Eigen::Vector3d& n0, double depth_m) {
  PlaneFit fit;
  std::vector<double> offsets;
  offsets.reserve(points.size());
  for (const RoiPoint& p : points) offsets.push_back(n0.dot(p.p_lidar));
  const double d0 = Median(offsets);
  // A plane through the sensor's origin is not a board in view (and has no w).
  if (!(std::abs(d0) > 0.0)) return fit;
  Eigen::Vector3d w = n0 / d0;
  double cutoff = depth_m;
  double sigma = 0.0;
  Eigen::Matrix3d H = Eigen::Matrix3d::Zero();
  std::vector<double> abs_r;
  for (int it = 0; it < kPlaneIterations; ++it) {
    abs_r.clear();
    for (const RoiPoint& p : points) {
      const double r = std::abs(RangeResidual(w, p.p_lidar));
      if (r < cutoff) abs_r.push_back(r);
    }
    if (static_cast<int>(abs_r.size()) < kMinPlanePoints) return fit;
    sigma = std::max(kMadToSigma * Median(abs_r), kMinPlaneSigmaM);
    const double next_cutoff = std::min(kTukeyC * sigma, depth_m);
    H.setZero();
    Eigen::Vector3d g = Eigen::Vector3d::Zero();
    for (const RoiPoint& p : points) {
      const double r = RangeResidual(w, p.p_lidar);
      const double u = r / next_cutoff;
      if (!(std::abs(u) < 1.0)) continue;
      // d r / d w for r = range - 1 / (w . ray), with the exact ray direction of the return.
      const Eigen::Vector3d ray = p.p_lidar.normalized();
      const double wu = w.dot(ray);
      const Eigen::Vector3d J = ray / (wu * wu);
      const double weight = (1.0 - u * u) * (1.0 - u * u);
      H += weight * J * J.transpose();
      g += weight * J * r;
    }
    const Eigen::LDLT<Eigen::Matrix3d> ldlt(H);
    if (ldlt.info() != Eigen::Success || !ldlt.isPositive()) return fit;
    const Eigen::Vector3d next_w = w - ldlt.solve(g);
    if (!next_w.allFinite() || next_w.norm() == 0.0) return fit;
    const double change = (next_w - w).norm() / w.norm() + std::abs(next_cutoff - cutoff);
    w = next_w;
    cutoff = next_cutoff;
    if (change < kConvergence) break;
  }
  // w = n / d for either orientation of n: report n on the side of n0.
  const double side = w.dot(n0) > 0.0 ? 1.0 : -1.0;
  fit.n_lidar = side * w.normalized();
  fit.d_m = side / w.norm();
  fit.cutoff_m = cutoff;
  // Cov(w) = sigma^2 H^-1; n = w / |w| moves by (I - n n^T) dw / |w|.
  const Eigen::Matrix3d P = Eigen::Matrix3d::Identity() - fit.n_lidar * fit.n_lidar.transpose();
  fit.cov_w = H.inverse() * (sigma * sigma);
  const Eigen::Matrix3d cov_n = P * fit.cov_w * P * (fit.d_m * fit.d_m);
  fit.normal_sigma_rad = std::sqrt(
      std::max(Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(cov_n).eigenvalues()(2), 0.0));
  fit.ok = true;
  return fit;
}

// How many frames' worth of independent errors each frame's edge floor and the profiles
// (WidenByProfiles) count for, per ring: like the quantisation they are a function of where the
// boundary falls on the ring's firing grid, so the same boundary in two frames whose grids lie
// a phase difference d (in steps) apart is taken as correlated by the sawtooth's
// rho(d) = 1 - 6 frac(d) (1 - frac(d)) (1 at d = 0, 0 on average over a uniform d, -1/2 at
// half a step). The variance of the frames' mean is the single frame's times (1 / N^2) sum
// over frame pairs of rho; the fit's covariance already divides by N, so this returns
// (1 / N) sum rho, the median over the rings: N when all frames fired at the same azimuths (a
// phase-locked sensor), about 1 for a free-running one. (The quantisation itself correlates
// every edge pair across frames exactly, QuantisationB.)
double FrameRepeats(const std::vector<int>& group_ring, const std::vector<int>& group_frame,
                    const std::vector<double>& group_phase) {
  std::map<int, std::map<int, double>> phases;  // ring -> frame -> phase
  for (std::size_t g = 0; g < group_ring.size(); ++g) {
    if (std::isfinite(group_phase[g])) phases[group_ring[g]][group_frame[g]] = group_phase[g];
  }
  std::vector<double> repeats;
  for (const auto& [ring, by_frame] : phases) {
    double sum = 0.0;
    for (const auto& [frame_a, phase_a] : by_frame) {
      for (const auto& [frame_b, phase_b] : by_frame) {
        const double d = phase_a - phase_b;
        const double frac = d - std::floor(d);
        sum += 1.0 - 6.0 * frac * (1.0 - frac);
      }
    }
    // The sum is never negative (rho is a covariance); grids spread evenly over the step
    // (N of them) bring it down to 1 / N, the least it can be.
    const double n = static_cast<double>(by_frame.size());
    repeats.push_back(std::max(sum / n, 1.0 / n));
  }
  return repeats.empty() ? 1.0 : Median(repeats);
}

// The covariance of two sawtooth errors, each uniform within half a step, of edges whose
// boundaries lie f steps apart along rings that fire on one azimuth grid (one ring, or the
// rings of one rotation, whose firing offsets are fixed): B2(frac f) / 2 = 1/12 - f (1 - f) / 2,
// in steps^2. f is known only to sigma_f steps (the pose's own error moves the boundaries);
// the covariance is averaged over that. The cusp at f = 0 makes the average matter: two
// rings crossing a vertical side a twelfth of a step apart in phase are nearly one error or
// nearly two, and taking the fitted f as exact made the rotation's sigma swing with it,
// smallest where the error was largest.
double SawtoothCovariance(double f, double sigma_f) {
  constexpr double kTwoPiSq = 2.0 * std::numbers::pi * std::numbers::pi;
  const auto exact = [](double x) {
    const double frac = x - std::floor(x);
    return 1.0 / 12.0 - 0.5 * frac * (1.0 - frac);
  };
  if (!std::isfinite(sigma_f)) return 0.0;
  if (sigma_f < 1e-3) return exact(f);
  if (sigma_f < 0.1) {
    // Gauss-Hermite, 7 points: smooth enough over the cusp at this width.
    constexpr std::array<double, 4> kNodes = {0.0, 0.8162878828589647, 1.6735516287674714,
                                              2.6519613568352334};
    constexpr std::array<double, 4> kWeights = {0.8102646175568073, 0.4256072526101278,
                                                0.05451558281912703, 0.0009717812450995192};
    const double scale = std::numbers::sqrt2 * sigma_f;
    double sum = kWeights[0] * exact(f);
    for (int i = 1; i < 4; ++i)
      sum += kWeights[i] * (exact(f + kNodes[i] * scale) + exact(f - kNodes[i] * scale));
    return sum / std::sqrt(std::numbers::pi);
  }
  // Wider: the Fourier series sum cos(2 pi k f) / (2 pi^2 k^2), each term damped by the
  // Gaussian's exp(-2 pi^2 k^2 sigma^2); beyond k = 8 the damping leaves under 1e-5.
  double sum = 0.0;
  for (int k = 1; k <= 8; ++k) {
    const double kk = static_cast<double>(k * k);
    sum += std::exp(-kTwoPiSq * kk * sigma_f * sigma_f) * std::cos(2.0 * std::numbers::pi * k * f) /
           (kTwoPiSq * kk);
  }
  return sum;
}

// SawtoothCovariance(f, sigma_f) for sigma_f below kTabledSigmaMax, interpolated bilinearly in
// a table of frac(f) x sigma_f built once (steps of 1/512 by 0.0025, 82 KiB): QuantisationB
// evaluates it for every pair of edges of all frames (~10^6 for a Pandar64 board over 10
// rotations), where seven evaluations of the sawtooth per pair cost more. The table's nodes
// are SawtoothCovariance's own values, linear between them; the cusp at f = 0 lies on a node.
constexpr double kTabledSigmaMax = 0.1;
double TabledSawtoothCovariance(double f, double sigma_f) {
  constexpr int kCols = 512;  // frac(f)
  constexpr int kRows = 40;   // sigma_f
  if (!(sigma_f < kTabledSigmaMax)) return SawtoothCovariance(f, sigma_f);
  static const std::vector<float> table = [] {
    std::vector<float> t((kRows + 1) * (kCols + 1));
    for (int r = 0; r <= kRows; ++r) {
      for (int c = 0; c <= kCols; ++c) {
        t[r * (kCols + 1) + c] = static_cast<float>(SawtoothCovariance(
            static_cast<double>(c) / kCols, kTabledSigmaMax * static_cast<double>(r) / kRows));
      }
    }
    return t;
  }();
  const double x = (f - std::floor(f)) * kCols;
  const double y = sigma_f * (kRows / kTabledSigmaMax);
  const int c = std::min(static_cast<int>(x), kCols - 1);
  const int r = std::min(static_cast<int>(y), kRows - 1);
  const double u = x - c, v = y - r;
  const float* row = &table[r * (kCols + 1) + c];
  const float* next = row + (kCols + 1);
  return (1.0 - v) * ((1.0 - u) * row[0] + u * row[1]) + v * ((1.0 - u) * next[0] + u * next[1]);
}

// The edges' quantisation errors as the sandwich's middle: sum over all edge pairs, of one
// rotation or of two, of SawtoothCovariance(their boundaries' separation) (w a J)_i (w a J)_j^T,
// with `pose_covariance` (x, y, theta) giving each separation's uncertainty. An edge's
// steps_along counts from its ring's first point in its own rotation, a point of that
// rotation's firing grid, so the separation of two edges of different rotations includes the
// rotations' phase difference: the same boundary in two rotations d of a step apart correlates
// as 1 - 6 d (1 - d), fully when they fired at the same azimuths (a phase-locked sensor). Only
// same-rotation pairs, scaled by a per-rotation-pair factor (FrameRepeats), made the
// cross-rotation covariance of two different boundaries f apart 12 B(f) B(d) instead of
// B(f + d) (B the sawtooth's covariance), and the VLP-16's sigma on a free-running motor came
// out 8% too small. With `same_frame_only`, the pairs of one rotation alone (a first estimate
// of `pose_covariance` needs no more). Cost: O(edges^2).
Eigen::Matrix3d QuantisationB(const std::vector<Edge>& edges, const std::vector<int>& group_frame,
                              bool same_frame_only, const std::vector<Eigen::Vector3d>& wJa,
                              const std::vector<double>& true_steps,
                              const std::vector<Eigen::Vector3d>& steps_dpose,
                              const Eigen::Matrix3d& pose_covariance) {
  // Per edge, its crossing's sensitivity s (steps per pose unit) and P s, P the pose
  // covariance: a pair's sigma_f^2 = (s_i - s_j)^T P (s_i - s_j) = s_i P s_i + s_j P s_j -
  // 2 s_i P s_j. Edges whose crossing does not move with the pose have an infinite sigma_f.
  const std::size_t n = edges.size();
  std::vector<Eigen::Vector3d> Ps(n);
  std::vector<double> sPs(n);
  for (std::size_t i = 0; i < n; ++i) {
    Ps[i] = pose_covariance * steps_dpose[i];
    sPs[i] = steps_dpose[i].dot(Ps[i]);
  }
  // B = sum_i v_i v_i^T / 12 + sum_{i<j} c_ij (v_i v_j^T + v_j v_i^T): with w_i = sum_{j>i}
  // c_ij v_j, the second sum is sum_i (v_i w_i^T + w_i v_i^T), one 3-vector update per pair
  // (the pairs of all frames are many: ~10^6 for a Pandar64 board over 10 rotations).
  Eigen::Matrix3d B = Eigen::Matrix3d::Zero();
  for (std::size_t i = 0; i < n; ++i) {
    if (wJa[i].isZero()) continue;
    Eigen::Vector3d w = Eigen::Vector3d::Zero();
    const bool finite_i = std::isfinite(sPs[i]);
    for (std::size_t j = i + 1; j < n; ++j) {
      if (same_frame_only && group_frame[edges[j].group] != group_frame[edges[i].group]) break;
      if (wJa[j].isZero()) continue;
      const double var_f = sPs[i] + sPs[j] - 2.0 * steps_dpose[i].dot(Ps[j]);
      const double sigma_f = finite_i && std::isfinite(sPs[j])
                                 ? std::sqrt(std::max(var_f, 0.0))
                                 : std::numeric_limits<double>::infinity();
      // The boundaries' separation along the rings, not the edges': those are whole steps
      // apart by construction.
      w += TabledSawtoothCovariance(true_steps[i] - true_steps[j], sigma_f) * wJa[j];
    }
    const Eigen::Matrix3d outer = wJa[i] * w.transpose();
    B += (1.0 / 12.0) * wJa[i] * wJa[i].transpose() + outer + outer.transpose();
  }
  return B;
}

// With few rings through the holes the board rests on a few chords, and a chord's half length
// c = sqrt(r^2 - h^2) places a ring at h from a hole's centre through dh = -c dc / h: near the
// centre a chord a step short moves the board by centimetres, far more (and in a direction)
// than the fit's linearisation at its own solution shows. So does its rotation, which the y of
// the holes left and right of the centre sets. The profile of the edges' whitened cost
// (each edge's quantisation variance, truncated at `gate_m`) along `direction` in
// (x, y, theta) — a unit of the component profiled, the others moving with it — gives the
// honest spread: the farthest move within `reach` whose cost is within `repeats` of the
// least (the cost takes every edge as an independent error; `repeats` is FrameRepeats, the
// frames' worth each frame's edges count for: 1 for one rotation or a free-running motor's,
// N for N rotations that fired at the same azimuths and so repeat one rotation's errors).
// Returns its square (of `direction`'s unit).
double ProfileVariance(const std::vector<Edge>& edges, const std::vector<double>& weights,
                       const std::vector<Circle>& holes, const Eigen::Vector2d& half_page,
                       const Eigen::Vector3d& pose, double gate_m, const Eigen::Vector3d& direction,
                       double step, double reach, double repeats) {
  const int n = static_cast<int>(reach / step);
  std::vector<double> cost(2 * n + 1, 0.0);
  for (int i = -n; i <= n; ++i) {
    const Eigen::Vector3d moved = pose + (i * step) * direction;
    const Eigen::Matrix2d R = Rotation2(moved.z());
    double c = 0.0;
    for (std::size_t k = 0; k < edges.size(); ++k) {
      if (!(weights[k] > 0.0)) continue;  // the fit's outliers stay out
      Eigen::Vector2d grad;
      int which = -1;
      const double r = NearestBoundary(
          holes, half_page, R.transpose() * (edges[k].p_plane - moved.head<2>()), &grad, &which);
      const double along = grad.dot(R.transpose() * edges[k].step_plane);
      c += std::min(r * r, gate_m * gate_m) / (along * along / 12.0 + kEdgeFloorVarM2);
    }
    cost[i + n] = c;
  }
  const double least = *std::min_element(cost.begin(), cost.end());
  double farthest = 0.0;
  for (int i = -n; i <= n; ++i)
    if (cost[i + n] <= least + repeats) farthest = std::max(farthest, std::abs(i * step));
  return farthest * farthest;
}

// Two passes: the second fits the plane to the points the first pass's board pose puts on
// paper, clear of the edges: the region also holds the board's stand, a post touching its
// back below the page, whose points tilt the plane by a few tenths of a degree.
constexpr int kPasses = 2;
// A point within half a ring step of an edge of the page or a hole (where the edge fit
// places it to) may be off the paper; the second pass's plane leaves those out, and this
// much more. A fixed 2 cm (a step at 6 m) left out a third of a 16-ring board's points at
// 3.6 m, and the normal's error grew by a fifth.
constexpr double kPaperMarginM = 0.003;

// The model every step matches the returns to: the hole circles of the drawing with their
// feature ids, in feature order, and half the page.
struct HoleModel {
  std::vector<Circle> holes;
  Eigen::Vector2d half_page = Eigen::Vector2d::Zero();
};

// Needs a round-hole board; gives its holes (each hole centre feature with the hole shape
// around it) and half its page size.
HoleModel MakeHoleModel(const Board& board) {
  HoleModel model;
  for (const BoardFeature& f : board.features()) {
    if (f.kind != FeatureKind::kHoleCentre) continue;
    for (const BoardShape& s : board.shapes()) {
      if (s.paint == Paint::kHole && (s.centre_board() - f.p_board).norm() < 0.5 * s.radius_m()) {
        model.holes.push_back({f.p_board, s.radius_m(), f.id});
      }
    }
  }
  model.half_page = 0.5 * board.page_size_m();
  return model;
}

// Step 1's result: the returns near the expected board, and what stands in front of it.
struct Roi {
  std::vector<RoiPoint> points;
  // Returns between the sensor and the board whose rays would meet the region: occluders
  // (another board's stand, a person), by ring and frame (frame * 2^16 + ring), azimuth.
  std::map<int, std::vector<double>> occluders;
};

// Step 1. Needs the frames, the prior's inverse and the options' margins; gives the finite
// returns within the page plus roi_margin_m and within roi_depth_m of the expected plane (in
// the expected board frame), and the occluders: returns more than kOccluderDepthM in front of
// that plane whose rays meet the region. One transform per point.
Roi CollectRoi(std::span<const std::span<const RoundHoleCloudPoint>> frames,
               const Rigid3d& T_board_lidar_prior, const Eigen::Vector2d& half_page,
               const RoundHoleCloudOptions& options) {
  Roi roi;
  const Eigen::Vector3d sensor_board = T_board_lidar_prior.translation();
  for (std::size_t f = 0; f < frames.size(); ++f) {
    for (const RoundHoleCloudPoint& p : frames[f]) {
      const Eigen::Vector3d p_lidar(p.x, p.y, p.z);
      if (!p_lidar.allFinite()) continue;
      const Eigen::Vector3d q = T_board_lidar_prior * p_lidar;
      if (std::abs(q.x()) < half_page.x() + options.roi_margin_m &&
          std::abs(q.y()) < half_page.y() + options.roi_margin_m &&
          std::abs(q.z()) < options.roi_depth_m) {
        roi.points.push_back({p_lidar, p.ring, static_cast<int>(f)});
      }
      if (q.z() > kOccluderDepthM && q.z() < sensor_board.z()) {
        // Where its ray meets the expected plane (board z = 0).
        const Eigen::Vector3d m =
            sensor_board + (sensor_board.z() / (sensor_board.z() - q.z())) * (q - sensor_board);
        if (std::abs(m.x()) < half_page.x() + options.roi_margin_m &&
            std::abs(m.y()) < half_page.y() + options.roi_margin_m) {
          roi.occluders[static_cast<int>(f) * 65536 + p.ring].push_back(std::atan2(p.y, p.x));
        }
      }
    }
  }
  return roi;
}

// Needs the ROI's points and the prior's inverse; gives how many rings cross the page: one
// ring across it is a line, which determines no plane, let alone the holes (a board far or
// small for the ring spacing). A ring crosses the page when its points span half the page's
// width, which a board's stand (a 6 cm post) never does.
std::ptrdiff_t RingsAcrossPage(const std::vector<RoiPoint>& roi, const Rigid3d& T_board_lidar_prior,
                               const Eigen::Vector2d& half_page) {
  std::map<int, std::pair<double, double>> ring_span_m;
  for (const RoiPoint& p : roi) {
    const double x = (T_board_lidar_prior * p.p_lidar).x();
    std::pair<double, double>& span = ring_span_m.try_emplace(p.ring, x, x).first->second;
    span = {std::min(span.first, x), std::max(span.second, x)};
  }
  return std::count_if(ring_span_m.begin(), ring_span_m.end(), [&](const auto& span) {
    return span.second.second - span.second.first > half_page.x();
  });
}

// Plane coordinates: origin o at the expected page centre's foot on the fitted plane, ex
// along the expected x projected on it, ey = n x ex (LiDAR frame).
struct PlaneFrame {
  Eigen::Vector3d o = Eigen::Vector3d::Zero();
  Eigen::Vector3d ex = Eigen::Vector3d::Zero();
  Eigen::Vector3d ey = Eigen::Vector3d::Zero();
};

// Needs the prior and a fitted plane; gives the plane's coordinates (PlaneFrame).
PlaneFrame MakePlaneFrame(const Rigid3d& T_lidar_board_prior, const Eigen::Matrix3d& R_prior,
                          const PlaneFit& plane) {
  const Eigen::Vector3d n = plane.n_lidar;
  PlaneFrame frame;
  frame.o = T_lidar_board_prior.translation() -
            (n.dot(T_lidar_board_prior.translation()) - plane.d_m) * n;
  frame.ex = (R_prior.col(0) - R_prior.col(0).dot(n) * n).normalized();
  frame.ey = n.cross(frame.ex);
  return frame;
}

// Occluders' azimuths relative to the expected board centre's, sorted, by ring and frame.
using OccluderAzimuths = std::map<int, std::vector<double>>;

// Needs step 1's occluders and the reference azimuth; gives their azimuths on the scale the
// in-plane points use (InPlane::azimuth_rad), sorted for Occluded.
OccluderAzimuths RelativeOccluders(const std::map<int, std::vector<double>>& occluders,
                                   double azimuth0) {
  OccluderAzimuths occluder_azimuths;
  for (const auto& [group, azimuths] : occluders) {
    std::vector<double>& a = occluder_azimuths[group];
    for (double az : azimuths) a.push_back(std::remainder(az - azimuth0, 2.0 * std::numbers::pi));
    std::sort(a.begin(), a.end());
  }
  return occluder_azimuths;
}

// True when a ray of ring-frame `group` between azimuths lo and hi hit something in front
// of the board: a gap there, or the ring's end, is the occluder's, not a hole's or the page's.
bool Occluded(const OccluderAzimuths& occluders, int group, double lo, double hi) {
  const auto it = occluders.find(group);
  if (it == occluders.end()) return false;
  const auto first = std::upper_bound(it->second.begin(), it->second.end(), lo);
  return first != it->second.end() && *first < hi;
}

// A plane inlier moved along its ray onto the plane.
struct InPlane {
  Eigen::Vector2d p_plane;
  // Azimuth about the spin axis (LiDAR z), relative to the expected board centre's, so that a
  // ring's points sort in firing order whatever azimuth the rotation starts at.
  double azimuth_rad = 0.0;
  int group = 0;  // frame * 2^16 + ring (rings are < 2^16): one ring of one frame
};

// Step 3's result.
struct PlaneInliers {
  std::vector<InPlane> points;
  double sum_r2 = 0.0;    // of their range residuals, m^2
  std::size_t rings = 0;  // distinct rings among them
};

// Step 3. Needs the ROI, the fitted plane with its coordinates and the reference azimuth;
// gives the points within the plane fit's cut-off, moved along their rays onto the plane.
PlaneInliers ProjectInliers(const std::vector<RoiPoint>& roi, const PlaneFit& plane,
                            const PlaneFrame& frame, double azimuth0) {
  const Eigen::Vector3d n = plane.n_lidar;
  PlaneInliers inliers;
  std::set<int> plane_rings;
  for (const RoiPoint& p : roi) {
    const double r = RangeResidual(n / plane.d_m, p.p_lidar);
    const double along = n.dot(p.p_lidar);
    if (!(std::abs(r) < plane.cutoff_m)) continue;
    inliers.sum_r2 += r * r;
    const Eigen::Vector3d q = (plane.d_m / along) * p.p_lidar - frame.o;
    const double azimuth =
        std::remainder(std::atan2(p.p_lidar.y(), p.p_lidar.x()) - azimuth0, 2.0 * std::numbers::pi);
    inliers.points.push_back(
        {Eigen::Vector2d(q.dot(frame.ex), q.dot(frame.ey)), azimuth, p.frame * 65536 + p.ring});
    plane_rings.insert(p.ring);
  }
  inliers.rings = plane_rings.size();
  return inliers;
}

// Step 4's result: the ring edges and the coarse search's samples, with what the covariance
// needs of each group (a ring of one frame, on the board, with at least two points).
struct RingEdges {
  std::vector<Edge> edges;
  std::vector<Sample> samples;
  std::vector<int> group_ring;
  std::vector<int> group_frame;
  std::vector<double> group_phase;  // per group with a step: see Edge::step_plane
  int gaps = 0;                     // gaps found so far: the next Edge::gap
};

// One board ring's points (sorted by azimuth) and its median azimuth step, for the edges.
struct RingView {
  const std::vector<InPlane>& points;
  double step = 0.0;
  double a0 = 0.0;  // the ring's first azimuth

  // One azimuth step of the ring at point a, towards b, in the plane.
  Eigen::Vector2d StepVector(std::size_t a, std::size_t b) const {
    const double da = points[b].azimuth_rad - points[a].azimuth_rad;
    return Eigen::Vector2d((points[b].p_plane - points[a].p_plane) * (step / da));
  }
  // Point i's azimuth in steps from the ring's first point, plus `half`.
  double StepsAlong(std::size_t i, double half) const {
    return (points[i].azimuth_rad - a0) / step + half;
  }
};

// Needs a board ring [begin, end) with a positive step; adds the edges of its gaps wider than
// kGapSteps steps and not occluded, and its samples: every point (paper) and the missing rays
// of each such gap (not paper).
void AddRingGaps(const RingView& ring, std::size_t begin, std::size_t end,
                 const OccluderAzimuths& occluders, int group, RingEdges* out) {
  const std::vector<InPlane>& in_plane = ring.points;
  const int key = in_plane[begin].group;
  for (std::size_t i = begin; i < end; ++i) {
    out->samples.push_back({in_plane[i].p_plane, true});
    if (i + 1 == end) break;
    const double da = in_plane[i + 1].azimuth_rad - in_plane[i].azimuth_rad;
    if (da <= kGapSteps * ring.step ||
        Occluded(occluders, key, in_plane[i].azimuth_rad, in_plane[i + 1].azimuth_rad)) {
      continue;
    }
    const Eigen::Vector2d s = ring.StepVector(i, i + 1);
    out->edges.push_back(
        {in_plane[i].p_plane + 0.5 * s, group, out->gaps, s, ring.StepsAlong(i, 0.5)});
    out->edges.push_back(
        {in_plane[i + 1].p_plane - 0.5 * s, group, out->gaps, s, ring.StepsAlong(i + 1, -0.5)});
    ++out->gaps;
    const int missing =
        static_cast<int>(std::min<double>(std::lround(da / ring.step) - 1, kMaxGapSamples));
    for (int k = 1; k <= missing; ++k) out->samples.push_back({in_plane[i].p_plane + k * s, false});
  }
}

// Whether an occluder's return lies within kEndSamples steps beyond a board ring's first or
// last point: the ring's end may be the occluder's shadow rather than the page's side.
struct HiddenEnds {
  bool start = false;
  bool end = false;
};

// A board ring of one frame: its points [begin, end) in the sorted in-plane points, its median
// azimuth step (0 when not positive) and whether occluders sit beyond its ends in this frame.
struct BoardRing {
  std::size_t begin = 0;
  std::size_t end = 0;
  double step = 0.0;
  HiddenEnds own;
};

// Needs a board ring [begin, end) of at least two points sorted by azimuth; gives its step and
// its own frame's hidden ends.
BoardRing MakeBoardRing(const std::vector<InPlane>& in_plane, std::size_t begin, std::size_t end,
                        const OccluderAzimuths& occluders) {
  BoardRing ring;
  ring.begin = begin;
  ring.end = end;
  std::vector<double> steps;
  for (std::size_t i = begin + 1; i < end; ++i)
    steps.push_back(in_plane[i].azimuth_rad - in_plane[i - 1].azimuth_rad);
  ring.step = std::max(Median(steps), 0.0);
  if (ring.step == 0.0) return ring;
  const int key = in_plane[begin].group;
  const double reach = kEndSamples * ring.step;
  const double first = in_plane[begin].azimuth_rad;
  const double last = in_plane[end - 1].azimuth_rad;
  ring.own = {Occluded(occluders, key, first - reach, first),
              Occluded(occluders, key, last, last + reach)};
  return ring;
}

// Needs every board ring of every frame; gives, per ring in the same order, which of its end
// edges to drop. Whether an occluder shows within reach of a ring's end depends on where the
// azimuth grid falls between the page's side and the occluder's: a rule on the frame's own
// returns keeps an edge only when its last point fell far from the side, and the kept edges
// then all lie inside the page by a fraction of a step (0.37 mm on average, 0.3 sigma of the
// board's x on the VLP-16 board that `front_vertical` half hides). So a frame's end is judged
// by the other frames of the same ring, whose grids a free-running motor puts at independent
// phases: any of them with an occluder there drops it. With one frame there is no other.
std::vector<HiddenEnds> EdgeHiding(const std::vector<InPlane>& in_plane,
                                   const std::vector<BoardRing>& rings) {
  struct Counts {
    int frames = 0;
    int hidden_starts = 0;
    int hidden_ends = 0;
  };
  std::map<int, Counts> per_ring;
  for (const BoardRing& r : rings) {
    Counts& n = per_ring[in_plane[r.begin].group % 65536];
    ++n.frames;
    n.hidden_starts += r.own.start ? 1 : 0;
    n.hidden_ends += r.own.end ? 1 : 0;
  }
  std::vector<HiddenEnds> hiding;
  hiding.reserve(rings.size());
  for (const BoardRing& r : rings) {
    const Counts& n = per_ring.at(in_plane[r.begin].group % 65536);
    if (n.frames == 1) {
      hiding.push_back(r.own);
      continue;
    }
    // The other frames' counts: this frame's own hidden end leaves it out.
    hiding.push_back(
        {n.hidden_starts - (r.own.start ? 1 : 0) > 0, n.hidden_ends - (r.own.end ? 1 : 0) > 0});
  }
  return hiding;
}

// Needs a board ring of at least two points sorted by azimuth and which of its end edges to
// drop; adds its group and, when its step is positive, its ends' edges (unless dropped) and
// virtual rays (unless its own frame has an occluder there), its firing phase and its gaps
// (AddRingGaps).
void AddBoardRing(const std::vector<InPlane>& in_plane, const BoardRing& board_ring,
                  const HiddenEnds& drop, const OccluderAzimuths& occluders, RingEdges* out) {
  const std::size_t begin = board_ring.begin;
  const std::size_t end = board_ring.end;
  const int group = static_cast<int>(out->group_ring.size());
  out->group_ring.push_back(in_plane[begin].group % 65536);
  out->group_frame.push_back(in_plane[begin].group / 65536);
  out->group_phase.push_back(std::numeric_limits<double>::quiet_NaN());
  const RingView ring{in_plane, board_ring.step, in_plane[begin].azimuth_rad};
  if (!(ring.step > 0.0)) return;
  const Eigen::Vector2d first_step = ring.StepVector(begin, begin + 1);
  const Eigen::Vector2d last_step = ring.StepVector(end - 2, end - 1);
  if (!drop.start)
    out->edges.push_back({in_plane[begin].p_plane - 0.5 * first_step, group, -1, first_step, -0.5});
  if (!drop.end) {
    out->edges.push_back({in_plane[end - 1].p_plane + 0.5 * last_step, group, -1, last_step,
                          ring.StepsAlong(end - 1, 0.5)});
  }
  // The ring's azimuth phase in this frame: whether the frames fired at the same
  // azimuths (then their edges share their quantisation errors).
  std::complex<double> phasor = 0.0;
  for (std::size_t i = begin; i < end; ++i)
    phasor += std::polar(1.0, 2.0 * std::numbers::pi * in_plane[i].azimuth_rad / ring.step);
  out->group_phase.back() = std::arg(phasor) / (2.0 * std::numbers::pi);
  for (int k = 1; k <= kEndSamples; ++k) {
    if (!board_ring.own.start)
      out->samples.push_back({in_plane[begin].p_plane - k * first_step, false});
    if (!board_ring.own.end)
      out->samples.push_back({in_plane[end - 1].p_plane + k * last_step, false});
  }
  AddRingGaps(ring, begin, end, occluders, group, out);
}

// Step 4. Needs the plane inliers (sorted here by ring and frame, then azimuth); gives the
// edges and samples of every ring on the board, ring by ring, frame by frame.
RingEdges ExtractEdges(std::vector<InPlane> in_plane, const Eigen::Vector2d& half_page,
                       const OccluderAzimuths& occluders) {
  std::sort(in_plane.begin(), in_plane.end(), [](const InPlane& a, const InPlane& b) {
    return a.group != b.group ? a.group < b.group : a.azimuth_rad < b.azimuth_rad;
  });
  std::vector<BoardRing> rings;
  for (std::size_t begin = 0; begin < in_plane.size();) {
    std::size_t end = begin;
    while (end < in_plane.size() && in_plane[end].group == in_plane[begin].group) ++end;
    // A ring's points on the plane spanning under a tenth of the page are not the board's:
    // the narrowest paper a ring crosses (hole to page side) is 0.12 of the page, and the
    // stand's post (6 cm), which a LiDAR below the board sees just behind its lower edge,
    // would otherwise give edges that pull the page down onto it.
    const bool board_ring = (in_plane[end - 1].p_plane - in_plane[begin].p_plane).norm() >=
                            kMinRingSpanPages * 2.0 * half_page.x();
    if (end - begin >= 2 && board_ring)
      rings.push_back(MakeBoardRing(in_plane, begin, end, occluders));
    begin = end;
  }
  const std::vector<HiddenEnds> drop = EdgeHiding(in_plane, rings);
  RingEdges out;
  for (std::size_t i = 0; i < rings.size(); ++i)
    AddBoardRing(in_plane, rings[i], drop[i], occluders, &out);
  return out;
}

// Step 5a. Needs the samples and the page raster; gives the in-plane pose (x, y, theta) on the
// coarse grid where the most samples agree with the drawing, ties to the one nearest the
// prior. About 10^6 raster look-ups.
Eigen::Vector3d CoarseSearch(const std::vector<Sample>& samples, const PaperRaster& raster,
                             const RoundHoleCloudOptions& options) {
  Eigen::Vector3d pose = Eigen::Vector3d::Zero();
  const std::size_t stride = samples.size() / kMaxSamples + 1;
  const int shifts = static_cast<int>(options.max_in_plane_shift_m / kShiftStepM);
  const int rotations = static_cast<int>(options.max_in_plane_rotation_rad / kRotationStepRad);
  int best_score = -1;
  double best_distance = 0.0;
  for (int ir = -rotations; ir <= rotations; ++ir) {
    const Eigen::Matrix2d Rt = Rotation2(ir * kRotationStepRad).transpose();
    for (int ix = -shifts; ix <= shifts; ++ix) {
      for (int iy = -shifts; iy <= shifts; ++iy) {
        const Eigen::Vector2d t(ix * kShiftStepM, iy * kShiftStepM);
        int score = 0;
        for (std::size_t i = 0; i < samples.size(); i += stride) {
          score += raster.PaperAt(Rt * (samples[i].p_plane - t)) == samples[i].paper ? 1 : 0;
        }
        // Ties go to the pose nearest the prior (1 radian weighs as 1 m).
        const double distance = t.squaredNorm() + std::pow(ir * kRotationStepRad, 2);
        if (score > best_score || (score == best_score && distance < best_distance)) {
          best_score = score;
          best_distance = distance;
          pose = Eigen::Vector3d(t.x(), t.y(), ir * kRotationStepRad);
        }
      }
    }
  }
  return pose;
}

// Step 5b's state and result: the robust Gauss-Newton of the edges to the outline and the
// hole circles, with what the covariance needs of its last iteration.
struct EdgeFit {
  Eigen::Vector3d pose = Eigen::Vector3d::Zero();  // (x, y, theta): p_plane = R(theta) m + (x, y)
  std::vector<int> which;      // per edge: the boundary it fits (NearestBoundary's `which`)
  std::vector<double> weight;  // per edge: its Tukey weight, 0 for an outlier
  Eigen::Matrix3d H = Eigen::Matrix3d::Zero();
  // Sum of w^2 J J^T kEdgeFloorVarM2 over the edges: the points' rounding.
  Eigen::Matrix3d B_floor = Eigen::Matrix3d::Zero();
  // Per edge: w J times its residual beyond the half step (signed as the residual), and which
  // crossing of its ring it is (2 * `which`, + 1 when the ring's step runs along the boundary's
  // gradient): see ExcessB.
  std::vector<Eigen::Vector3d> excess_wJ;
  std::vector<int> crossing;
  // Sum of w J (d r / d w): how the plane's error (w = n / d) moves the edges, which the
  // rays put where they meet the fitted plane, and with them the in-plane pose.
  Eigen::Matrix3d K = Eigen::Matrix3d::Zero();
  std::vector<Eigen::Vector3d> wJa;  // per edge: w J times the step seen through its normal
  std::vector<double> true_steps;    // per edge: where its boundary is, in steps along the ring
  std::vector<Eigen::Vector3d> steps_dpose;  // per edge: d true_steps / d pose
  double rms = 0.0;
  double last_gate = kInitialEdgeGateM;  // the edge fit's last robust gate, metres
  int kept = 0;
  bool degenerate = false;
};

// One iteration's sums besides those EdgeFit keeps.
struct EdgeSums {
  Eigen::Vector3d g = Eigen::Vector3d::Zero();
  std::vector<double> abs_r;  // kept edges' residuals beyond their half step
  double sum_r2 = 0.0;        // kept edges' squared residuals
};

// Needs the edges, the model, the plane's coordinates and the gate; gives one Gauss-Newton
// iteration's normal equations at fit->pose: fit's which, weight, H, B, K, wJa, true_steps,
// steps_dpose and kept, and `sums`.
void AccumulateEdges(const std::vector<Edge>& edges, const HoleModel& model,
                     const PlaneFrame& frame, double gate, EdgeFit* fit, EdgeSums* sums) {
  const Eigen::Vector3d& pose = fit->pose;
  const Eigen::Matrix2d R = Rotation2(pose.z());
  // d(R^T)/d(theta).
  Eigen::Matrix2d dRt;
  dRt << -std::sin(pose.z()), std::cos(pose.z()), -std::cos(pose.z()), -std::sin(pose.z());
  fit->H.setZero();
  fit->B_floor.setZero();
  fit->K.setZero();
  fit->wJa.assign(edges.size(), Eigen::Vector3d::Zero());
  fit->true_steps.assign(edges.size(), 0.0);
  fit->steps_dpose.assign(edges.size(), Eigen::Vector3d::Zero());
  fit->excess_wJ.assign(edges.size(), Eigen::Vector3d::Zero());
  fit->crossing.assign(edges.size(), 0);
  sums->g = Eigen::Vector3d::Zero();
  sums->abs_r.clear();
  sums->sum_r2 = 0.0;
  fit->kept = 0;
  for (std::size_t k = 0; k < edges.size(); ++k) {
    const Eigen::Vector2d e = edges[k].p_plane - pose.head<2>();
    Eigen::Vector2d grad;
    const double r =
        NearestBoundary(model.holes, model.half_page, R.transpose() * e, &grad, &fit->which[k]);
    double& weight = fit->weight[k];
    weight = 0.0;
    // The edge moves along its ring by up to half a step, seen through the boundary's
    // normal: only what lies beyond that can be an outlier (a chord through a stand's
    // post, an occluder, an edge of the wrong hole). Gating the residual itself dropped
    // and down-weighted edges at their quantisation's extremes, and the fit then swung
    // on the rest (the rotation by up to a degree on a 16-ring board).
    const double along = grad.dot(R.transpose() * edges[k].step_plane);
    const double excess = std::max(std::abs(r) - 0.5 * std::abs(along), 0.0);
    if (excess >= gate) continue;
    sums->abs_r.push_back(excess);
    const double u = excess / gate;
    weight = (1.0 - u * u) * (1.0 - u * u);
    Eigen::Vector3d J;
    J.head<2>() = -(R * grad);
    J.z() = grad.dot(dRt * e);
    fit->H += weight * J * J.transpose();
    sums->g += weight * J * r;
    // Beyond the quantisation (below), what the edge's residual shows past the half step
    // (a chord grazing a hole, where the model is far from linear; the stand's post), and a
    // floor. Not r^2 - step^2 / 12: a quantisation error exceeds its RMS 42% of the time, and
    // that would count it twice.
    fit->B_floor += weight * weight * kEdgeFloorVarM2 * J * J.transpose();
    fit->excess_wJ[k] = weight * std::copysign(excess, r) * J;
    fit->crossing[k] = 2 * fit->which[k] + (along > 0.0 ? 1 : 0);
    fit->wJa[k] = weight * along * J;
    // How the boundary's crossing of the ring (in steps) moves with the pose.
    fit->steps_dpose[k] = std::abs(along) > kMinAlongM
                              ? Eigen::Vector3d(-J / along)
                              : Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity());
    // Where the fitted boundary crosses the ring, in steps: the edge moved by the residual
    // along the ring (at most the half step it can be off by).
    fit->true_steps[k] =
        edges[k].steps_along - (std::abs(along) > 0.0 ? std::clamp(r / along, -0.5, 0.5) : 0.0);
    // A ray meets the plane w . p = 1 at p = ray / (w . ray): dp / dw = -p p^T; the edge
    // residual sees the in-plane part of that through the boundary's normal.
    const Eigen::Vector3d p_edge =
        frame.o + edges[k].p_plane.x() * frame.ex + edges[k].p_plane.y() * frame.ey;
    const Eigen::Vector2d normal_plane = R * grad;
    const Eigen::Vector3d normal_lidar = normal_plane.x() * frame.ex + normal_plane.y() * frame.ey;
    fit->K -= weight * J * (normal_lidar.dot(p_edge) * p_edge.transpose());
    sums->sum_r2 += r * r;
    ++fit->kept;
  }
}

// Step 5b. Needs the edges, the model and the plane's coordinates, fit->pose the start (the
// coarse search's, or the last pass's fit) and fit->last_gate the last pass's gate; gives the
// fitted pose and everything EdgeFit holds of the last iteration. degenerate when the edges
// do not fix the board along y (no ring through a hole) or at all.
void FitEdges(const std::vector<Edge>& edges, const HoleModel& model, const PlaneFrame& frame,
              EdgeFit* fit) {
  fit->which.assign(edges.size(), -1);
  fit->weight.assign(edges.size(), 0.0);
  double gate = kInitialEdgeGateM;
  fit->H.setZero();
  fit->rms = 0.0;
  fit->kept = 0;
  fit->degenerate = false;
  EdgeSums sums;
  for (int it = 0; it < kEdgeIterations; ++it) {
    AccumulateEdges(edges, model, frame, gate, fit, &sums);
    if (fit->kept < kMinEdges) break;
    fit->rms = std::sqrt(sums.sum_r2 / fit->kept);
    // Singular: the edges do not fix the board along y (no ring through a hole) or at all.
    const Eigen::LDLT<Eigen::Matrix3d> ldlt(fit->H);
    if (ldlt.info() != Eigen::Success || !ldlt.isPositive()) {
      fit->degenerate = true;
      break;
    }
    const Eigen::Vector3d dx = ldlt.solve(-sums.g);
    if (!dx.allFinite()) {
      fit->degenerate = true;
      break;
    }
    fit->pose += dx;
    gate = std::max(kTukeyC * kMadToSigma * Median(sums.abs_r), kMinEdgeGateM);
    fit->last_gate = gate;
    if (dx.norm() < kConvergence) break;
  }
}

// Needs the ROI, a pass's plane, coordinates, edges and fitted pose; gives the ROI points that
// pose puts on paper farther than half the median ring step plus kPaperMarginM from every
// boundary: the next pass's plane points.
std::vector<RoiPoint> PointsOnPaper(const std::vector<RoiPoint>& roi, const Board& board,
                                    const HoleModel& model, const PlaneFit& plane,
                                    const PlaneFrame& frame, const std::vector<Edge>& edges,
                                    const Eigen::Vector3d& pose) {
  const Eigen::Vector3d n = plane.n_lidar;
  const Eigen::Matrix2d Rt = Rotation2(pose.z()).transpose();
  std::vector<double> step_lengths;
  for (const Edge& e : edges) step_lengths.push_back(e.step_plane.norm());
  const double inset = 0.5 * Median(step_lengths) + kPaperMarginM;
  std::vector<RoiPoint> plane_points;
  for (const RoiPoint& p : roi) {
    const double along = n.dot(p.p_lidar);
    if (along == 0.0) continue;
    const Eigen::Vector3d q = (plane.d_m / along) * p.p_lidar - frame.o;
    const Eigen::Vector2d m =
        Rt * (Eigen::Vector2d(q.dot(frame.ex), q.dot(frame.ey)) - pose.head<2>());
    Eigen::Vector2d grad;
    int boundary = -1;
    const Paint paint = board.PaintAt(m);
    if ((paint == Paint::kWhite || paint == Paint::kBlack) &&
        std::abs(NearestBoundary(model.holes, model.half_page, m, &grad, &boundary)) > inset) {
      plane_points.push_back(p);
    }
  }
  return plane_points;
}

// What steps 2-5b leave for the result: the last pass's plane, coordinates, edges and fit.
struct BoardFitState {
  PlaneFit plane;
  PlaneFrame frame;
  RingEdges rings;
  EdgeFit fit;
};

// Steps 2-5b, in kPasses passes (the second refits the plane to the points on paper). Needs
// the ROI, the model and the prior; gives the last pass's state in *state, and false (with
// out->reason) when a pass finds no plane like the board's or too few rings on it. Fills out's
// plane fields.
bool FitPlaneAndEdges(const Board& board, const HoleModel& model, const Roi& roi,
                      const Rigid3d& T_lidar_board_prior, const RoundHoleCloudOptions& options,
                      BoardFitState* state, RoundHoleCloudDetection* out) {
  const Eigen::Matrix3d R_prior = T_lidar_board_prior.RotationMatrix();
  const Eigen::Vector3d n0 = R_prior.col(2);
  std::vector<RoiPoint> plane_points = roi.points;
  const PaperRaster raster(board);
  for (int pass = 0; pass < kPasses; ++pass) {
    // 2. Plane.
    const PlaneFit& plane = state->plane = FitPlane(plane_points, n0, options.roi_depth_m);
    out->reason = RoundHoleCloudReason::kNoPlane;
    if (!plane.ok || plane.cutoff_m > kTukeyC * kMaxPlaneSigmaM ||
        std::acos(std::clamp(plane.n_lidar.dot(n0), -1.0, 1.0)) > options.max_tilt_rad) {
      return false;
    }

    // 3. Inliers moved along their rays onto the plane, in plane coordinates.
    state->frame = MakePlaneFrame(T_lidar_board_prior, R_prior, plane);
    const double azimuth0 = std::atan2(state->frame.o.y(), state->frame.o.x());
    PlaneInliers inliers = ProjectInliers(roi.points, plane, state->frame, azimuth0);
    out->plane_inliers = static_cast<int>(inliers.points.size());
    if (out->plane_inliers < kMinPlanePoints) return false;
    out->plane_rms_m = std::sqrt(inliers.sum_r2 / out->plane_inliers);
    out->normal_sigma_rad = plane.normal_sigma_rad;
    // Fewer than two rings on the board: not even the plane is determined by them.
    if (inliers.rings < 2) {
      out->reason = RoundHoleCloudReason::kTooFewRingsThroughHoles;
      return false;
    }

    // 4. Edges and coarse-search samples, ring by ring.
    state->rings = ExtractEdges(std::move(inliers.points), model.half_page,
                                RelativeOccluders(roi.occluders, azimuth0));

    // 5a. Coarse search of the in-plane pose: the most samples where the drawing agrees. The
    // second pass starts from the first pass's pose (its plane differs by a fraction of a
    // degree, which moves the page by a fraction of a millimetre).
    if (pass == 0) state->fit.pose = CoarseSearch(state->rings.samples, raster, options);

    // 5b. Robust Gauss-Newton of all edges to the outline and the hole circles, from the pose.
    FitEdges(state->rings.edges, model, state->frame, &state->fit);
    if (state->fit.degenerate || pass + 1 == kPasses) break;
    plane_points = PointsOnPaper(roi.points, board, model, plane, state->frame, state->rings.edges,
                                 state->fit.pose);
  }
  return true;
}

// Rings through holes: gaps whose two edges both fit the same hole.
struct HoleRings {
  std::vector<std::set<int>> per_hole;  // the rings through each hole
  int total = 0;                        // distinct rings through any
};

// Needs the edges and their fit; gives the rings through each hole.
HoleRings RingsThroughHoles(const RingEdges& rings, const EdgeFit& fit, std::size_t holes) {
  const std::vector<Edge>& edges = rings.edges;
  HoleRings out;
  out.per_hole.resize(holes);
  std::set<int> rings_through;
  for (std::size_t k = 0; k + 1 < edges.size(); ++k) {
    if (edges[k].gap < 0 || edges[k + 1].gap != edges[k].gap) continue;
    if (fit.weight[k] > 0.0 && fit.weight[k + 1] > 0.0 && fit.which[k] >= 0 &&
        fit.which[k] == fit.which[k + 1]) {
      out.per_hole[fit.which[k]].insert(rings.group_ring[edges[k].group]);
      rings_through.insert(rings.group_ring[edges[k].group]);
    }
  }
  out.total = static_cast<int>(rings_through.size());
  return out;
}

// Needs the fitted plane, its coordinates and the in-plane pose; gives T_lidar_board.
Rigid3d BoardPose(const PlaneFit& plane, const PlaneFrame& frame, const Eigen::Vector3d& pose) {
  Eigen::Matrix3d R_lidar_plane;
  R_lidar_plane << frame.ex, frame.ey, plane.n_lidar;
  const Rigid3d T_lidar_plane(R_lidar_plane, frame.o);
  const Rigid3d T_plane_board(
      Eigen::Quaterniond(Eigen::AngleAxisd(pose.z(), Eigen::Vector3d::UnitZ())),
      Eigen::Vector3d(pose.x(), pose.y(), 0.0));
  return T_lidar_plane * T_plane_board;
}

// The edges' residuals beyond their half step as the sandwich's middle: what the quantisation
// does not explain is a misfit of the model (the stand's post seen behind the page's lower edge
// continues a ring's run of points; a ring grazing a hole or running along the page's top or
// bottom leaves it through a curve), and the same ring meets it again in every rotation. So the
// excess of one crossing (ring, boundary, direction: `crossing`) is summed over the rotations
// before it is squared: N^2 times one rotation's for N rotations showing one excess, whatever
// their phases, as the pose error it causes does not average down. Summed per edge and
// scaled by FrameRepeats (about 1 for a free-running motor), it had left the VLP-16 boards' y
// 1.3 times its sigma over 10 free-running rotations at 2.5-4 m, one board's post alone
// 2.9 sigma; phase-locked rotations and single ones get what they had. Cost: O(edges log
// edges).
Eigen::Matrix3d ExcessB(const std::vector<Edge>& edges, const std::vector<int>& group_ring,
                        const EdgeFit& fit) {
  std::map<std::pair<int, int>, Eigen::Vector3d> by_crossing;
  for (std::size_t k = 0; k < edges.size(); ++k) {
    if (fit.excess_wJ[k].isZero()) continue;
    const std::pair<int, int> key(group_ring[edges[k].group], fit.crossing[k]);
    by_crossing.try_emplace(key, Eigen::Vector3d::Zero()).first->second += fit.excess_wJ[k];
  }
  Eigen::Matrix3d B = Eigen::Matrix3d::Zero();
  for (const auto& [key, sum] : by_crossing) B += sum * sum.transpose();
  return B;
}

// Covariance of the pose, board frame, (theta_x, theta_y, theta_z, t_x, t_y, t_z). Needs the
// last pass's state and the pose it gives (T_lidar_board). Assigned in place, not returned:
// Eigen evaluates a returned sum of products in another order, which moved the last bits.
// In-plane (t_x, t_y, theta_z): the sandwich H^-1 B H^-1 of the edges' quantisation errors
// (each edge uniform within half a step along its ring), through the fit's Jacobian — a ring
// that crosses a hole near its centre hardly places the board's y, one near its top or
// bottom does. Frames that fired at the same azimuths repeat those errors exactly, so their
// edges count once, not once per frame; frames at other phases share them partly
// (QuantisationB, over every pair of edges of all frames). The edges' misfit beyond the
// quantisation repeats in every frame (ExcessB); `repeats` is FrameRepeats.
// The plane's error moves the in-plane pose too: by -H^-1 K dw (the rays' meeting points
// slide across the plane as it moves, by tan(incidence) of its shift).
void PoseCovariance(const BoardFitState& state, const Rigid3d& T_lidar_board, double repeats,
                    Eigen::Matrix<double, 6, 6>* pose_covariance) {
  const EdgeFit& fit = state.fit;
  const RingEdges& rings = state.rings;
  const Eigen::Matrix3d H_inv = fit.H.inverse();
  const Eigen::Matrix3d B_misfit =
      ExcessB(rings.edges, rings.group_ring, fit) + fit.B_floor * repeats;
  // The quantisation's correlations need the boundaries' separations, which the pose places
  // only to its own uncertainty: first without it (and, as a first estimate, with the pairs
  // of other rotations taken as FrameRepeats says), then with the covariance that gives.
  const Eigen::Matrix3d B_first =
      QuantisationB(rings.edges, rings.group_frame, true, fit.wJa, fit.true_steps, fit.steps_dpose,
                    Eigen::Matrix3d::Zero());
  const Eigen::Matrix3d cov_first = H_inv * (B_misfit + B_first * repeats) * H_inv;
  const Eigen::Matrix3d B_quantisation = QuantisationB(
      rings.edges, rings.group_frame, false, fit.wJa, fit.true_steps, fit.steps_dpose, cov_first);
  const Eigen::Matrix3d cov_quantisation = H_inv * (B_misfit + B_quantisation) * H_inv;
  const Eigen::Matrix3d dpose_dw = -H_inv * fit.K;
  Eigen::Matrix3d A = Eigen::Matrix3d::Zero();  // (dx, dy, dtheta) -> (t_x, t_y, theta_z)
  A.topLeftCorner<2, 2>() = Rotation2(-fit.pose.z());
  A(2, 2) = 1.0;
  // Out of the plane (theta_x, theta_y, t_z), from the plane fit's covariance of w = n / d:
  // the normal moves by d (I - n n^T) dw and the plane at the board's centre c by -d c . dw.
  const PlaneFit& plane = state.plane;
  const Eigen::Matrix3d R_lb = T_lidar_board.RotationMatrix();
  Eigen::Matrix3d G;
  G.row(0) = -plane.d_m * R_lb.col(1).transpose();
  G.row(1) = plane.d_m * R_lb.col(0).transpose();
  G.row(2) = -plane.d_m * T_lidar_board.translation().transpose();
  // pose error = M_q q + M_w dw for the in-plane quantisation error q and the plane's dw.
  Eigen::Matrix<double, 6, 3> M_q = Eigen::Matrix<double, 6, 3>::Zero();
  Eigen::Matrix<double, 6, 3> M_w = Eigen::Matrix<double, 6, 3>::Zero();
  const std::array<int, 3> in_index = {3, 4, 2}, out_index = {0, 1, 5};
  const Eigen::Matrix3d in_from_w = A * dpose_dw;
  for (int a = 0; a < 3; ++a) {
    M_q.row(in_index[a]) = A.row(a);
    M_w.row(in_index[a]) = in_from_w.row(a);
    M_w.row(out_index[a]) = G.row(a);
  }
  *pose_covariance = M_q * cov_quantisation * M_q.transpose() + M_w * plane.cov_w * M_w.transpose();
}

// With kFewRingsThroughHoles or fewer rings through the holes: widens the board's y and
// rotation variances in *pose_covariance to their profiles' (ProfileVariance). Needs the edges,
// their fit and FrameRepeats. The profile's cost takes every edge as an independent error, so
// N rotations that fired at the same azimuths (their edges the same N times over) made it N
// times as steep and the profile's variance N times too small (less where it reached the
// hole's radius), though they say no more than one: the VLP-16's theta_z came out 15% too
// small on phase-locked pairs of rotations (error / sigma 1.15 over 1,000 boards, 1.02 with
// one rotation). The profile's threshold is therefore FrameRepeats instead of 1: N for those,
// about 1 for a free-running motor, whose rotations' errors do average down.
void WidenByProfiles(const std::vector<Edge>& edges, const EdgeFit& fit, const HoleModel& model,
                     double repeats, Eigen::Matrix<double, 6, 6>* pose_covariance) {
  const Eigen::Vector3d& pose = fit.pose;
  double reach = 0.0;
  for (const Circle& c : model.holes) reach = std::max(reach, c.radius_m);
  // y along the board's own y, x and rotation held: nothing else moves with it by symmetry.
  const Eigen::Vector3d along_y(-std::sin(pose.z()), std::cos(pose.z()), 0.0);
  const double y_profile = ProfileVariance(edges, fit.weight, model.holes, model.half_page, pose,
                                           fit.last_gate, along_y, 1e-3, reach, repeats);
  (*pose_covariance)(4, 4) = std::max((*pose_covariance)(4, 4), y_profile);
  // The rotation with x and y as the fit moves them with it (H^-1's column), reaching as far
  // as turns the outer holes by a radius.
  const Eigen::Matrix3d H_inv = fit.H.inverse();
  const Eigen::Vector3d with_theta = H_inv.col(2) / H_inv(2, 2);
  double outer = 0.0;
  for (const Circle& c : model.holes) outer = std::max(outer, c.centre_board.norm());
  const double theta_profile =
      ProfileVariance(edges, fit.weight, model.holes, model.half_page, pose, fit.last_gate,
                      with_theta, 5e-4, reach / outer, repeats);
  (*pose_covariance)(2, 2) = std::max((*pose_covariance)(2, 2), theta_profile);
}
}  // namespace

bool RoundHoleCloudOptions::Valid() const {
  const auto finite = [](double v) { return std::isfinite(v); };
  return finite(roi_margin_m) && roi_margin_m > 0.0 && finite(roi_depth_m) && roi_depth_m > 0.0 &&
         finite(max_tilt_rad) && max_tilt_rad > 0.0 && max_tilt_rad < 0.5 * std::numbers::pi &&
         finite(max_in_plane_shift_m) && max_in_plane_shift_m >= 0.0 &&
         finite(max_in_plane_rotation_rad) && max_in_plane_rotation_rad >= 0.0 &&
         min_rings_through_holes >= 1;
}

const char* RoundHoleCloudReasonName(RoundHoleCloudReason reason) {
  switch (reason) {
    case RoundHoleCloudReason::kNone:
      return "";
    case RoundHoleCloudReason::kBadInput:
      return "bad_input";
    case RoundHoleCloudReason::kBoardNotInRoi:
      return "board_not_in_roi";
    case RoundHoleCloudReason::kNoPlane:
      return "no_plane";
    case RoundHoleCloudReason::kTooFewRingsThroughHoles:
      return "too_few_rings_through_holes";
    case RoundHoleCloudReason::kFitFailed:
      return "fit_failed";
  }
  return "unknown";
}

RoundHoleCloudDetection DetectRoundHoleBoardInCloud(
    const Board& board, std::span<const std::span<const RoundHoleCloudPoint>> frames,
    const Rigid3d& T_lidar_board_prior, const RoundHoleCloudOptions& options) {
  RoundHoleCloudDetection out;
  const Eigen::Matrix4d prior_matrix = T_lidar_board_prior.Matrix();
  if (board.type() != BoardType::kRoundHole || !options.Valid() || !prior_matrix.allFinite())
    return out;
  const HoleModel model = MakeHoleModel(board);

  // 1. Region of interest, in the expected board frame.
  const Rigid3d T_board_lidar_prior = T_lidar_board_prior.Inverse();
  const Roi roi = CollectRoi(frames, T_board_lidar_prior, model.half_page, options);
  out.roi_points = static_cast<int>(roi.points.size());
  if (out.roi_points < kMinPlanePoints) {
    out.reason = RoundHoleCloudReason::kBoardNotInRoi;
    return out;
  }
  if (RingsAcrossPage(roi.points, T_board_lidar_prior, model.half_page) < 2) {
    out.reason = RoundHoleCloudReason::kTooFewRingsThroughHoles;
    return out;
  }

  // 2-5b. Plane, inliers on it, edges, coarse search and edge fit.
  BoardFitState state;
  if (!FitPlaneAndEdges(board, model, roi, T_lidar_board_prior, options, &state, &out)) return out;
  const EdgeFit& fit = state.fit;
  out.edges = fit.kept;
  out.edge_rms_m = fit.rms;

  const HoleRings hole_rings = RingsThroughHoles(state.rings, fit, model.holes.size());
  out.rings_through_holes = hole_rings.total;
  if (out.rings_through_holes < options.min_rings_through_holes) {
    out.reason = RoundHoleCloudReason::kTooFewRingsThroughHoles;
    return out;
  }
  out.reason = RoundHoleCloudReason::kFitFailed;
  // An edge fit that left the coarse search's range by as much again has slid onto wrong
  // associations (edges of one hole on another).
  if (fit.degenerate || fit.kept < kMinEdges || fit.rms > kMaxEdgeRmsM ||
      fit.pose.head<2>().norm() > 2.0 * options.max_in_plane_shift_m) {
    return out;
  }
  out.T_lidar_board = BoardPose(state.plane, state.frame, fit.pose);
  const double repeats =
      FrameRepeats(state.rings.group_ring, state.rings.group_frame, state.rings.group_phase);
  PoseCovariance(state, out.T_lidar_board, repeats, &out.pose_covariance);
  if (out.rings_through_holes <= kFewRingsThroughHoles)
    WidenByProfiles(state.rings.edges, fit, model, repeats, &out.pose_covariance);
  const Eigen::Matrix2d cov_in = out.pose_covariance.block<2, 2>(3, 3);
  out.in_plane_sigma_m = Eigen::Vector2d(std::sqrt(cov_in(0, 0)), std::sqrt(cov_in(1, 1)));
  for (std::size_t i = 0; i < model.holes.size(); ++i) {
    const Circle& hole = model.holes[i];
    out.holes.push_back(
        {hole.id,
         out.T_lidar_board * Eigen::Vector3d(hole.centre_board.x(), hole.centre_board.y(), 0.0),
         static_cast<int>(hole_rings.per_hole[i].size())});
  }
  out.found = true;
  out.reason = RoundHoleCloudReason::kNone;
  return out;
}

}  // namespace linecal
