#include "detectors/circle/circle_detector.h"

#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <optional>
#include <utility>
#include <vector>

#include "detectors/circle/circle_blobs.h"
#include "detectors/circle/circle_edge_fit.h"
#include "detectors/common/ellipse.h"
#include "detectors/common/homography.h"

namespace linecal {
namespace {

// ---- The board model --------------------------------------------------------------------

// What the detector needs to know about the circle board, derived from Board (so a scaled
// board works unchanged).
struct CircleBoardModel {
  std::vector<Eigen::Vector2d> p_board;  // circle centres by feature id, metres
  std::vector<bool> light;               // true: a white circle on black
  double radius_m = 0.0;
  std::array<int, 2> pair = {-1, -1};  // the black pair, left then right
  Eigen::Vector2d pair_mid = Eigen::Vector2d::Zero();
  std::vector<int> rotated;                   // the id at the 180-degree image of each circle
  std::vector<int> growth_order;              // ids other than the pair, nearest to pair_mid first
  std::vector<Eigen::Vector2d> dark_points;   // printed black; their 180-degree images white
  std::vector<Eigen::Vector2d> light_points;  // the 180-degree images of dark_points
  Eigen::Vector2d black_reference = Eigen::Vector2d::Zero();  // black between circles
};

Eigen::Vector2d Rotate180(const Eigen::Vector2d& p, const Eigen::Vector2d& centre) {
  return 2.0 * centre - p;
}

std::optional<CircleBoardModel> MakeModel(const Board& board) {
  CircleBoardModel m;
  for (const BoardShape& shape : board.shapes()) {
    if (shape.geometry == ShapeGeometry::kCircle) {
      m.radius_m = shape.radius_m();
      break;
    }
  }
  std::vector<int> dark;
  for (const BoardFeature& f : board.features()) {
    m.p_board.push_back(f.p_board);
    const bool light = board.PaintAt(f.p_board) == Paint::kWhite;
    m.light.push_back(light);
    if (!light) dark.push_back(f.id);
  }
  if (dark.size() != 2 || !(m.radius_m > 0.0)) return std::nullopt;
  if (m.p_board[dark[0]].x() > m.p_board[dark[1]].x()) std::swap(dark[0], dark[1]);
  m.pair = {dark[0], dark[1]};
  m.pair_mid = 0.5 * (m.p_board[dark[0]] + m.p_board[dark[1]]);
  const int n = static_cast<int>(m.p_board.size());
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector2d image = Rotate180(m.p_board[i], m.pair_mid);
    int best = 0;
    for (int j = 1; j < n; ++j) {
      if ((m.p_board[j] - image).norm() < (m.p_board[best] - image).norm()) best = j;
    }
    m.rotated.push_back(best);
    if (i != m.pair[0] && i != m.pair[1]) m.growth_order.push_back(i);
  }
  std::stable_sort(m.growth_order.begin(), m.growth_order.end(), [&](int a, int b) {
    return (m.p_board[a] - m.pair_mid).norm() < (m.p_board[b] - m.pair_mid).norm();
  });
  // docs/boards.md: the black areas span PDF y 50..550 while the rows of circles span 100..380,
  // so PDF y 455 (75 mm below the last row's centres, 50 mm clear of its circles) is black
  // in every strip, and its image under the grid's 180-degree symmetry, PDF y 25, lies in
  // the middle of the white top margin. Board frame: PDF (x, y) -> (x - 450, 300 - y) mm.
  const double mm = 1e-3 * board.params().scale;
  for (const double x_pdf : {100.0, 300.0, 450.0, 600.0, 800.0}) {
    const Eigen::Vector2d p = mm * Eigen::Vector2d(x_pdf - 450.0, 300.0 - 455.0);
    m.dark_points.push_back(p);
    m.light_points.push_back(Rotate180(p, m.pair_mid));
  }
  // PDF (350, 135): black, 61 mm from the nearest circle centres; symmetric to PDF
  // (550, 345), also black.
  m.black_reference = mm * Eigen::Vector2d(350.0 - 450.0, 300.0 - 135.0);
  return m;
}

// ---- 2. Identification ------------------------------------------------------------------

double GreyAt(const ImageView8& image, const Eigen::Vector2d& uv) {
  if (!uv.allFinite()) return std::numeric_limits<double>::quiet_NaN();
  // Clamped before the conversion, which far-off points would overflow.
  const int x = static_cast<int>(std::lround(std::clamp(uv.x(), 0.0, image.width - 1.0)));
  const int y = static_cast<int>(std::lround(std::clamp(uv.y(), 0.0, image.height - 1.0)));
  return image.At(x, y);
}

// The mean grey of the 3 x 3 pixels around uv (clamped to the image): a noise-robust sample
// for the coarse tests of paint.
double BoxGrey(const ImageView8& image, const Eigen::Vector2d& uv) {
  double sum = 0.0;
  for (int dy = -1; dy <= 1; ++dy) {
    for (int dx = -1; dx <= 1; ++dx) sum += GreyAt(image, uv + Eigen::Vector2d(dx, dy));
  }
  return sum / 9.0;
}

// The homography of the affine map that takes the black pair's board positions to the
// blobs `left` and `right`: the board x axis from the pair, the y axis from the metric of
// their ellipses (an ellipse is the image of a circle: S = R^2 A A^T for the local affine
// map A, so A is S^1/2 / R times a rotation, and the print seen from the front fixes the
// reflection).
//
// undo_edge_shift: the blobs' threshold moves their edges by about the same number of
// pixels all round (blur with gamma: 2-3 px on dark circles of 12 px at 50 degrees), which
// changes a foreshortened ellipse's aspect: its minor axis loses a larger part. Along a_x
// the printed circle reaches exactly radius |a_x| (the image of its point (radius, 0)), so
// the blobs' reach there gives that shift, and each semi-axis gets it back. The estimate
// can also mislead (two hard renders of the smallest circles pitched 50 degrees lost their
// grid with it: CircleDetectorTest.SmallestCirclesUnderTheHardEffects), so the search
// seeds with the blobs as they are first.
Eigen::Matrix3d PairAffine(const CircleBoardModel& m, const CircleBlob& left,
                           const CircleBlob& right, bool undo_edge_shift) {
  const Eigen::Vector2d a_x = (right.ellipse.centre - left.ellipse.centre) /
                              (m.p_board[m.pair[1]] - m.p_board[m.pair[0]]).norm();
  Eigen::Matrix2d shape = 0.5 * (left.shape + right.shape);
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> axes(shape);
  if (undo_edge_shift && axes.info() == Eigen::Success && axes.eigenvalues().minCoeff() > 0.0) {
    const Eigen::Vector2d u = a_x.normalized();
    const double reach_px = 1.0 / std::sqrt(u.dot(shape.inverse() * u));
    const double shift_px = m.radius_m * a_x.norm() - reach_px;
    const Eigen::Vector2d semi = (axes.eigenvalues().cwiseSqrt().array() + shift_px).matrix();
    if (semi.minCoeff() > 0.0) {
      shape = axes.eigenvectors() * semi.cwiseAbs2().asDiagonal() * axes.eigenvectors().transpose();
    }
  }
  const Eigen::Matrix2d s = shape / (m.radius_m * m.radius_m);
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(s);
  const Eigen::Matrix2d root = eig.operatorSqrt();
  const Eigen::Matrix2d root_inverse = eig.operatorInverseSqrt();
  const Eigen::Vector2d q1 = (root_inverse * a_x).normalized();
  Eigen::Vector2d a_y = root * Eigen::Vector2d(-q1.y(), q1.x());
  a_y *= a_x.norm() / (root * q1).norm();
  // Board x right and y up appear, in the image (v down), with a negative cross product.
  if (a_x.x() * a_y.y() - a_x.y() * a_y.x() > 0.0) a_y = -a_y;
  Eigen::Matrix3d h = Eigen::Matrix3d::Identity();
  h.block<2, 1>(0, 0) = a_x;
  h.block<2, 1>(0, 1) = a_y;
  const Eigen::Vector2d mid_px = 0.5 * (left.ellipse.centre + right.ellipse.centre);
  h.block<2, 1>(0, 2) = mid_px - a_x * m.pair_mid.x() - a_y * m.pair_mid.y();
  return h;
}

// The image radius of a board circle at p_board under H: the mean of the images of its
// radii along board x and y. Pixels.
double ImageRadius(const Eigen::Matrix3d& H, const Eigen::Vector2d& p_board, double radius_m) {
  const Eigen::Vector2d c = ApplyHomography(H, p_board);
  const double rx = (ApplyHomography(H, p_board + Eigen::Vector2d(radius_m, 0.0)) - c).norm();
  const double ry = (ApplyHomography(H, p_board + Eigen::Vector2d(0.0, radius_m)) - c).norm();
  return 0.5 * (rx + ry);
}

// Fewer blob matches than this do not make a grid worth measuring: a homography over 12 of
// the 30 circles spread across the board predicts the rest within a fraction of a radius,
// and the 4 circles next to the bar may merge with it under blur at the smallest sizes.
constexpr int kMinMatchedBlobs = 12;

struct Grid {
  Eigen::Matrix3d H = Eigen::Matrix3d::Identity();  // board metres -> image pixels
  std::vector<int> blob;                            // per id, a blob index or -1
};

// Grows the grid from the pair (blobs `left`, `right`) outwards, seeded by PairAffine with
// undo_edge_shift; nullopt when fewer than kMinMatchedBlobs circles match.
std::optional<Grid> GrowGrid(const CircleBoardModel& m, const std::vector<CircleBlob>& blobs,
                             int left, int right, bool undo_edge_shift) {
  Grid g;
  g.blob.assign(m.p_board.size(), -1);
  g.blob[m.pair[0]] = left;
  g.blob[m.pair[1]] = right;
  std::vector<bool> used(blobs.size(), false);
  used[left] = used[right] = true;
  Eigen::Matrix3d H = PairAffine(m, blobs[left], blobs[right], undo_edge_shift);
  std::vector<Eigen::Vector2d> src = {m.p_board[m.pair[0]], m.p_board[m.pair[1]]};
  std::vector<Eigen::Vector2d> dst = {blobs[left].ellipse.centre, blobs[right].ellipse.centre};
  HomographyFitOptions fast;
  fast.refine = false;
  for (const int id : m.growth_order) {
    const Eigen::Vector2d predicted = ApplyHomography(H, m.p_board[id]);
    const double radius = ImageRadius(H, m.p_board[id], m.radius_m);
    if (!predicted.allFinite() || !(radius > 0.0)) return std::nullopt;
    // Neighbouring circles are 2.8 radii apart or more: a blob within 0.6 radii of the
    // prediction is this circle, and the tolerance absorbs the affine seed's error.
    double best_distance = 0.6 * radius;
    int best = -1;
    for (std::size_t b = 0; b < blobs.size(); ++b) {
      if (used[b] || blobs[b].light != m.light[id]) continue;
      // CircleBlob sizes follow the threshold under blur: a factor of 2 either way.
      if (blobs[b].radius_px < 0.5 * radius || blobs[b].radius_px > 2.0 * radius) continue;
      const double d = (blobs[b].ellipse.centre - predicted).norm();
      if (d < best_distance) {
        best_distance = d;
        best = static_cast<int>(b);
      }
    }
    if (best < 0) continue;
    g.blob[id] = best;
    used[best] = true;
    src.push_back(m.p_board[id]);
    dst.push_back(blobs[best].ellipse.centre);
    // Five points spread over two rows or more determine a homography (four would fit any
    // four points exactly, leaving no check).
    if (src.size() >= 5) {
      if (const std::optional<HomographyFit> fit = FitHomography(src, dst, fast)) H = fit->H;
    }
  }
  if (static_cast<int>(src.size()) < kMinMatchedBlobs) return std::nullopt;
  const std::optional<HomographyFit> fit = FitHomography(src, dst);
  if (!fit) return std::nullopt;
  // CircleBlob centroids are the thresholded regions' (biased by blur and perspective by a small
  // fraction of the radius): half a radius separates a consistent grid from a wrong one.
  for (std::size_t i = 0; i < src.size(); ++i) {
    const double radius = ImageRadius(fit->H, src[i], m.radius_m);
    if ((ApplyHomography(fit->H, src[i]) - dst[i]).norm() > 0.5 * radius) return std::nullopt;
  }
  g.H = fit->H;
  return g;
}

// ---- 4./5. Perspective, verification, orientation ---------------------------------------

struct Measured {
  std::vector<Eigen::Vector2d> uv;  // per id
};

enum class Outcome { kFound, kFailed };

Outcome MeasureBoard(const ImageView8& image, const CircleBoardModel& m, const Grid& grid,
                     const CircleOptions& options, Measured* out) {
  const std::size_t n = m.p_board.size();
  const CircleEdgeFitter fitter(options.edge_rays);
  std::vector<Eigen::Vector2d> centres(n);
  std::vector<double> radii(n);
  // Measures circle `id` seeded by the ellipse that H predicts.
  auto measure = [&](const Eigen::Matrix3d& H, std::size_t id) {
    const std::optional<Ellipse> predicted =
        EllipseFromConic(ImageOfCircle(H, m.p_board[id], m.radius_m));
    if (!predicted) return false;
    const std::optional<Ellipse> e =
        fitter.Measure(image, *predicted, m.light[id], options.min_contrast);
    if (!e) return false;
    centres[id] = e->centre;
    radii[id] = std::sqrt(e->semi_major * e->semi_minor);
    return true;
  };
  for (std::size_t id = 0; id < n; ++id) {
    if (!measure(grid.H, id)) return Outcome::kFailed;
  }
  std::vector<Eigen::Vector2d> corrected = centres;
  std::optional<HomographyFit> fit;
  // Fits H to the centres, corrected for perspective when asked. The offset changes by
  // (change of H) x (offset / radius), tiny after the first round; three rounds leave it
  // below 1e-4 px.
  auto correct = [&]() {
    corrected = centres;
    fit = FitHomography(m.p_board, corrected);
    if (!options.correct_perspective) return fit.has_value();
    for (int round = 0; round < 3 && fit; ++round) {
      for (std::size_t id = 0; id < n; ++id) {
        const std::optional<Ellipse> image_ellipse =
            EllipseFromConic(ImageOfCircle(fit->H, m.p_board[id], m.radius_m));
        if (!image_ellipse) return false;
        corrected[id] =
            centres[id] - (image_ellipse->centre - ApplyHomography(fit->H, m.p_board[id]));
      }
      fit = FitHomography(m.p_board, corrected);
    }
    return fit.has_value();
  };
  if (!correct()) return Outcome::kFailed;
  std::vector<double> residuals;
  HomographyResiduals(fit->H, m.p_board, corrected, &residuals);
  // A circle far off the board's homography was measured from a poor seed (the blob grid's
  // H): measure it again from the far better seed of the measured board, and refit. Far
  // off: 4 times the median residual and over half a pixel (noise of sigma 6 moves a
  // centre by about 0.2 px).
  std::vector<double> sorted = residuals;
  std::nth_element(sorted.begin(), sorted.begin() + n / 2, sorted.end());
  const double outlier_px = std::max(0.5, 4.0 * sorted[n / 2]);
  const Eigen::Matrix3d seed_H = fit->H;
  bool remeasured = false;
  for (std::size_t id = 0; id < n; ++id) {
    if (residuals[id] <= outlier_px) continue;
    if (!measure(seed_H, id)) return Outcome::kFailed;
    remeasured = true;
  }
  if (remeasured) {
    if (!correct()) return Outcome::kFailed;
    HomographyResiduals(fit->H, m.p_board, corrected, &residuals);
  }
  for (std::size_t id = 0; id < n; ++id) {
    if (!(residuals[id] <= options.max_residual_radius_fraction * radii[id])) {
      return Outcome::kFailed;
    }
  }
  // Orientation (header, step 5), against the contrast of the bar and the black near it.
  auto grey = [&](const Eigen::Vector2d& p_board) {
    const Eigen::Vector2d uv = ApplyHomography(fit->H, p_board);
    return BoxGrey(image, uv);
  };
  const double contrast = grey(m.pair_mid) - grey(m.black_reference);
  if (!(contrast >= options.min_contrast)) return Outcome::kFailed;
  double score = 0.0;
  for (std::size_t i = 0; i < m.dark_points.size(); ++i) {
    score += grey(m.light_points[i]) - grey(m.dark_points[i]);
  }
  score /= static_cast<double>(m.dark_points.size());
  // A quarter of the contrast: the margin and the strips' ends lie at the board's top and
  // bottom, where a 4:1 illumination gradient along the board can halve the white.
  const double min_score = 0.25 * contrast;
  out->uv.assign(n, Eigen::Vector2d::Zero());
  if (score >= min_score) {
    out->uv = corrected;
  } else if (score <= -min_score) {
    for (std::size_t id = 0; id < n; ++id) out->uv[id] = corrected[m.rotated[id]];
  } else {
    return Outcome::kFailed;
  }
  return Outcome::kFound;
}

Detection NotFound(DetectReason reason) {
  Detection d;
  d.found = false;
  d.reason = reason;
  return d;
}

// One search at a candidate resolution: found (or ambiguous), or nullopt with *reason.
std::optional<Detection> SearchAtFactor(const ImageView8& image, const Board& board,
                                        const CircleBoardModel& m, const CircleOptions& options,
                                        int factor, DetectReason* reason) {
  CircleBlobSearch search = FindCircleBlobs(image, factor, options.min_contrast, true, true);
  if (search.low_contrast) {
    *reason = DetectReason::kLowContrast;
    return std::nullopt;
  }
  const std::vector<CircleBlob>& blobs = search.blobs;
  if (blobs.empty()) {
    *reason = DetectReason::kNoCandidates;
    return std::nullopt;
  }
  const double expected_pair_distance =
      (m.p_board[m.pair[1]] - m.p_board[m.pair[0]]).norm() / m.radius_m;
  std::vector<bool> claimed(blobs.size(), false);
  *reason = DetectReason::kTooFewFeatures;
  std::optional<Measured> found;
  for (std::size_t i = 0; i < blobs.size(); ++i) {
    if (blobs[i].light) continue;
    for (std::size_t j = i + 1; j < blobs.size(); ++j) {
      if (blobs[j].light || claimed[i] || claimed[j]) continue;
      const CircleBlob& a = blobs[i];
      const CircleBlob& b = blobs[j];
      // Neighbours differ in size by a few percent under perspective, and the threshold
      // changes small blurred blobs by up to about a quarter.
      if (std::max(a.radius_px, b.radius_px) > 1.6 * std::min(a.radius_px, b.radius_px)) {
        continue;
      }
      const Eigen::Vector2d d = b.ellipse.centre - a.ellipse.centre;
      const Eigen::Matrix2d s_inverse = (0.5 * (a.shape + b.shape)).inverse();
      // The pair's distance in radii, measured in the ellipses' own metric (which removes
      // the local perspective): 4 on the printed board; the blob sizes' threshold bias
      // widens the band. That bias is a shift of the blobs' edges, about the same number of
      // pixels whatever their size, so small blobs get more room: dark circles of 12 px
      // under blur 1.5 and gamma 1.6 come out 1.8 px smaller in radius (ratio 1.41).
      const double ratio = std::sqrt(d.dot(s_inverse * d)) / expected_pair_distance;
      const double radius = 0.5 * (a.radius_px + b.radius_px);
      if (ratio < 0.7 || ratio > 1.4 * (radius + kMaxBlobEdgeShiftPx) / radius) continue;
      const Eigen::Vector2d mid = 0.5 * (a.ellipse.centre + b.ellipse.centre);
      if (!(GreyAt(image, mid) -
                std::max(GreyAt(image, a.ellipse.centre), GreyAt(image, b.ellipse.centre)) >=
            options.min_contrast)) {
        continue;
      }
      // The left circle of the pair is either blob: the orientation test settles it.
      // A pair of blobs shrunk by the threshold seeds the rows next to it a radius off
      // unless their edge shift is undone (PairAffine); seen as they are first, so that
      // blobs that are not shrunk ellipses keep the seed that finds them.
      std::optional<Grid> grid =
          GrowGrid(m, blobs, static_cast<int>(i), static_cast<int>(j), false);
      if (!grid) grid = GrowGrid(m, blobs, static_cast<int>(i), static_cast<int>(j), true);
      if (!grid) continue;
      Measured measured;
      if (MeasureBoard(image, m, *grid, options, &measured) != Outcome::kFound) {
        *reason = DetectReason::kVerificationFailed;
        continue;
      }
      if (found) return NotFound(DetectReason::kAmbiguous);
      found = measured;
      for (const int blob : grid->blob) {
        if (blob >= 0) claimed[blob] = true;
      }
    }
  }
  if (!found) return std::nullopt;
  Detection detection;
  detection.found = true;
  detection.reason = DetectReason::kNone;
  for (std::size_t id = 0; id < found->uv.size(); ++id) {
    DetectedFeature f;
    f.id = static_cast<int>(id);
    f.uv_px = found->uv[id];
    f.p_board = board.features()[id].p_board;
    detection.features.push_back(f);
  }
  return detection;
}

}  // namespace

std::string_view CircleOptions::Validate() const {
  if (min_contrast < 4 || min_contrast > 200) return "min_contrast";
  if (edge_rays < 16 || edge_rays > 256) return "edge_rays";
  if (!(max_residual_radius_fraction > 0.0 && max_residual_radius_fraction <= 1.0)) {
    return "max_residual_radius_fraction";
  }
  return {};
}

Detection DetectCircleBoard(const ImageView8& image, const Board& board,
                            const CircleOptions& options) {
  if (const DetectReason r =
          CheckDetectorInput(image, board, BoardType::kCircle, options.Validate().empty());
      r != DetectReason::kNone) {
    return NotFound(r);
  }
  const std::optional<CircleBoardModel> model = MakeModel(board);
  if (!model) return NotFound(DetectReason::kWrongBoard);
  // Coarse to fine: the candidate stage starts at the coarsest factor (a power of 2) whose
  // image still has kMinCandidatePixels, so that a large image costs little more than a
  // small one when its board is large, and ends at factor 2, which holds the smallest
  // circles (12 px).
  DetectReason reason = DetectReason::kNoCandidates;
  for (int factor = CoarsestCircleBlobFactor(image); factor >= 2; factor /= 2) {
    if (std::optional<Detection> d =
            SearchAtFactor(image, board, *model, options, factor, &reason)) {
      return *std::move(d);
    }
  }
  return NotFound(reason);
}

}  // namespace linecal
