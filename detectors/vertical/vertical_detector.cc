#include "detectors/vertical/vertical_detector.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <optional>
#include <span>
#include <tuple>
#include <utility>
#include <vector>

#include "detectors/common/corner_refine.h"
#include "detectors/common/edge_lines.h"
#include "detectors/common/homography.h"
#include "detectors/common/image_filters.h"

namespace linecal {
namespace {

// The page in cells (docs/boards.md §3: 300 x 1000 mm of 50 mm cells, the 4 x 18 pattern inside
// a one-cell white margin).
constexpr int kPageCols = 6;
constexpr int kPageRows = 20;
// Links along a run: the next corner lies within 25 degrees of the travel direction, as
// LinkXCorners' own tolerance (a board line bends far less between neighbouring vertices).
const double kCosRunTolerance = std::cos(25.0 * 3.14159265358979 / 180.0);
// The cell width across the middle line relative to the cell height along it: 1 in a frontal
// view, cos(50 deg) = 0.64 .. 1 / cos(50 deg) = 1.56 at docs/acceptance.md's largest yaw or pitch;
// the range leaves room for perspective and shear.
constexpr double kMinWidthRatio = 0.3;
constexpr double kMaxWidthRatio = 3.3;
// Width estimates of the rows of one run agree within 20 % with a straight line along the
// run: a wrong placement is off by a factor 2 or 1.5 (an edge at one cell taken for one at
// two or three), perspective bends the line by a few percent.
constexpr double kWidthAgreement = 0.2;
// Features are accepted within this fraction of their local cell of the prediction: a first
// homography from the run is good to a small fraction of a cell, a wrong edge is a whole
// cell away.
constexpr double kMaxPredictionCellFraction = 0.3;

// Grid coordinates: cell units on the page, gx right from its left edge, gy down from its top
// edge (the image's orientation for an upright board); page cell (c, r) spans
// [c, c + 1] x [r, r + 1], vertices are integer points.
struct LayoutFeature {
  int id = 0;
  int gx = 0;
  int gy = 0;
  FeatureKind kind = FeatureKind::kXCorner;
};

// The board as the detector sees it: page cell colours from Board::PaintAt at the cell
// centres, its features in grid coordinates, and the vertex column of the X-corners (the
// middle line).
struct Layout {
  double cell_m = 0.0;
  Eigen::Vector2d page_m = Eigen::Vector2d::Zero();
  std::array<std::array<bool, kPageCols>, kPageRows> black{};
  std::vector<LayoutFeature> features;
  int middle_gx = 0;
  std::vector<bool> x_corner_at_gy;  // per vertex row: the middle line has an X-corner there

  static bool OnPage(int c, int r) { return c >= 0 && c < kPageCols && r >= 0 && r < kPageRows; }
  bool Black(int c, int r) const { return OnPage(c, r) && black[r][c]; }
};

Layout MakeLayout(const Board& board) {
  Layout layout;
  layout.page_m = board.page_size_m();
  layout.cell_m = layout.page_m.x() / kPageCols;
  for (int r = 0; r < kPageRows; ++r) {
    for (int c = 0; c < kPageCols; ++c) {
      const Eigen::Vector2d p((c + 0.5) * layout.cell_m - 0.5 * layout.page_m.x(),
                              0.5 * layout.page_m.y() - (r + 0.5) * layout.cell_m);
      layout.black[r][c] = board.PaintAt(p) == Paint::kBlack;
    }
  }
  layout.x_corner_at_gy.assign(kPageRows + 1, false);
  for (const BoardFeature& f : board.features()) {
    LayoutFeature lf;
    lf.id = f.id;
    lf.gx =
        static_cast<int>(std::lround((f.p_board.x() + 0.5 * layout.page_m.x()) / layout.cell_m));
    lf.gy =
        static_cast<int>(std::lround((0.5 * layout.page_m.y() - f.p_board.y()) / layout.cell_m));
    lf.kind = f.kind;
    if (lf.kind == FeatureKind::kXCorner) {
      layout.middle_gx = lf.gx;
      layout.x_corner_at_gy[lf.gy] = true;
    }
    layout.features.push_back(lf);
  }
  return layout;
}

// ---- 1. Runs of X-corners --------------------------------------------------------------

// Straight runs of linked corners (index lists in order along the run), at least min_len
// and at most max_len long, each reported once. A run most of whose corners also have links
// across it is a line of a two-dimensional grid (a chessboard), not a middle line.
std::vector<std::vector<int>> StraightRuns(const std::vector<XCorner>& corners,
                                           const std::vector<std::array<int, 4>>& links,
                                           int min_len, int max_len) {
  const int n = static_cast<int>(corners.size());
  // The local direction of corner c closest to the image direction v.
  const auto closest = [&](int c, const Eigen::Vector2d& v) {
    int best = 0;
    for (int m = 1; m < 4; ++m) {
      if (XCornerDirection(corners[c], m).dot(v) > XCornerDirection(corners[c], best).dot(v)) {
        best = m;
      }
    }
    return best;
  };
  std::vector<std::vector<int>> runs;
  for (int start = 0; start < n; ++start) {
    for (int k = 0; k < 4; ++k) {
      if (links[start][k] < 0 || links[start][(k + 2) % 4] >= 0) continue;  // not a run's end
      std::vector<int> run = {start};
      int across = (links[start][(k + 1) % 4] >= 0 || links[start][(k + 3) % 4] >= 0) ? 1 : 0;
      int c = start;
      int m = k;
      while (links[c][m] >= 0 && static_cast<int>(run.size()) <= max_len) {
        const int next = links[c][m];
        const Eigen::Vector2d v = (corners[next].uv_px - corners[c].uv_px).normalized();
        if (XCornerDirection(corners[c], m).dot(v) < kCosRunTolerance) break;
        c = next;
        m = closest(c, v);
        if (XCornerDirection(corners[c], m).dot(v) < kCosRunTolerance) break;
        run.push_back(c);
        across += (links[c][(m + 1) % 4] >= 0 || links[c][(m + 3) % 4] >= 0) ? 1 : 0;
      }
      const int len = static_cast<int>(run.size());
      if (len < min_len || len > max_len || 2 * across > len) continue;
      if (run.front() > run.back()) continue;  // the same run walked from its other end
      runs.push_back(std::move(run));
    }
  }
  // Longest first: the most rows to place on the code.
  std::stable_sort(runs.begin(), runs.end(),
                   [](const auto& a, const auto& b) { return a.size() > b.size(); });
  return runs;
}

// ---- 2. Placing a run on the code ---------------------------------------------------------

// One walk across a cell row from the middle line.
struct Walk {
  bool start_dark = false;  // the cell next to the middle line is the darker of the two
  // Distance from the middle line to the first change of colour, px; kNone when there is
  // none within the walk, kUnknown when the walk left the image first.
  double dist_px = 0.0;
  Eigen::Vector2d crossing_px = Eigen::Vector2d::Zero();
};
constexpr double kNone = -1.0;
constexpr double kUnknown = -2.0;

// The walks of the rows between consecutive run corners: rows[j][s], s = 0 to the right of
// the run's travel direction (image, y down), s = 1 to its left; along[j] the row's height
// in px. False when a row has no contrast between the two cells beside the middle line.
bool WalkRows(const ImageF& blurred, const std::vector<XCorner>& corners,
              const std::vector<int>& run, double min_contrast,
              std::vector<std::array<Walk, 2>>* rows, std::vector<double>* along) {
  const int n_rows = static_cast<int>(run.size()) - 1;
  rows->assign(n_rows, {});
  along->assign(n_rows, 0.0);
  const auto inside = [&](const Eigen::Vector2d& p) {
    return p.x() >= 0.0 && p.y() >= 0.0 && p.x() <= blurred.width - 1.0 &&
           p.y() <= blurred.height - 1.0;
  };
  for (int j = 0; j < n_rows; ++j) {
    const XCorner& a = corners[run[j]];
    const XCorner& b = corners[run[j + 1]];
    const Eigen::Vector2d f = b.uv_px - a.uv_px;
    const double len = f.norm();
    const Eigen::Vector2d fu = f / len;
    const Eigen::Vector2d right(fu.y(), -fu.x());
    // Each corner's other line (the one across the run), oriented to the right.
    const auto across = [&](const XCorner& c) {
      Eigen::Vector2d d =
          std::abs(c.line_a.dot(fu)) < std::abs(c.line_b.dot(fu)) ? c.line_a : c.line_b;
      return d.dot(right) < 0.0 ? Eigen::Vector2d(-d) : d;
    };
    const Eigen::Vector2d e = (across(a) + across(b)).normalized();
    const Eigen::Vector2d mid = 0.5 * (a.uv_px + b.uv_px);
    (*along)[j] = len;
    // The first samples sit a fifth of a row height from the middle line (inside the
    // narrowest cell, kMinWidthRatio), and at least 2 px, beyond the blur of its edge.
    const double start = std::max(2.0, 0.2 * len);
    std::array<double, 2> v0;
    for (int s = 0; s < 2; ++s) {
      const Eigen::Vector2d p = mid + (s == 0 ? start : -start) * e;
      if (!inside(p)) return false;
      v0[s] = SampleBilinear(blurred, p.x(), p.y());
    }
    if (std::abs(v0[0] - v0[1]) < min_contrast) return false;
    const double threshold = 0.5 * (v0[0] + v0[1]);
    // Far enough for an edge three cells away in the widest view.
    const double max_dist = 3.2 * kMaxWidthRatio * len;
    constexpr double kStepPx = 0.5;  // below the blur: the crossing is interpolated
    for (int s = 0; s < 2; ++s) {
      Walk& w = (*rows)[j][s];
      const Eigen::Vector2d dir = s == 0 ? e : Eigen::Vector2d(-e);
      w.start_dark = v0[s] < threshold;
      w.dist_px = kNone;
      double prev = v0[s];
      for (double t = start + kStepPx; t <= max_dist; t += kStepPx) {
        const Eigen::Vector2d p = mid + t * dir;
        if (!inside(p)) {
          w.dist_px = kUnknown;
          break;
        }
        const double v = SampleBilinear(blurred, p.x(), p.y());
        if ((v < threshold) != w.start_dark) {
          const double t_cross = t - kStepPx + kStepPx * (threshold - prev) / (v - prev);
          w.dist_px = t_cross;
          w.crossing_px = mid + t_cross * dir;
          break;
        }
        prev = v;
      }
    }
  }
  return true;
}

// A run placed on the middle line: seed correspondences for the first homography.
struct Placement {
  std::vector<Eigen::Vector2d> grid;
  std::vector<Eigen::Vector2d> image;
  int gy_min = 0;
  int gy_max = 0;
};

// Every placement of the run (corner j at vertex (middle, g0 + dir j), dir = +1 or -1) that
// the walks fit: each row's colours beside the middle line, and its first change of colour
// at the distance in cells that the code gives, with a cell width that changes smoothly
// along the run.
std::vector<Placement> PlaceRun(const Layout& layout, const std::vector<XCorner>& corners,
                                const std::vector<int>& run,
                                const std::vector<std::array<Walk, 2>>& rows,
                                const std::vector<double>& along) {
  std::vector<Placement> placements;
  const int n = static_cast<int>(run.size());
  const int mx = layout.middle_gx;
  for (int dir : {1, -1}) {
    for (int g0 = 0; g0 <= kPageRows; ++g0) {
      const int g_last = g0 + dir * (n - 1);
      if (g_last < 0 || g_last > kPageRows) continue;
      bool ok = true;
      for (int j = 0; j < n && ok; ++j) ok = layout.x_corner_at_gy[g0 + dir * j];
      if (!ok) continue;
      std::vector<std::pair<int, double>> widths;      // (row j, cell width across, px)
      std::vector<std::tuple<int, double, int>> open;  // (row j, dist px, cells): page border
      for (int j = 0; j + 1 < n && ok; ++j) {
        const int r = dir > 0 ? g0 + j : g0 - j - 1;
        for (int s = 0; s < 2 && ok; ++s) {
          const int sgx = s == 0 ? dir : -dir;  // the walk's direction in gx
          const int cs = sgx > 0 ? mx : mx - 1;
          const bool start_black = layout.Black(cs, r);
          const Walk& w = rows[j][s];
          if (w.start_dark != start_black) {
            ok = false;
            break;
          }
          int d = 1;
          bool at_border = false;
          for (;; ++d) {
            const int c = cs + sgx * d;
            if (!Layout::OnPage(c, r)) {
              at_border = true;
              break;
            }
            if (layout.Black(c, r) != start_black) break;
          }
          if (w.dist_px == kUnknown) continue;
          if (at_border) {
            if (w.dist_px != kNone) open.emplace_back(j, w.dist_px, d);
            continue;
          }
          if (w.dist_px == kNone) {
            ok = false;
            break;
          }
          widths.emplace_back(j, w.dist_px / d);
        }
      }
      if (!ok || widths.size() < 2) continue;
      // The cell width along the run: a straight line in j by least squares (perspective
      // changes it smoothly, by a third over the board at 50 degrees of pitch).
      double sj = 0.0, sw = 0.0, sjj = 0.0, sjw = 0.0;
      for (const auto& [j, w] : widths) {
        sj += j;
        sw += w;
        sjj += static_cast<double>(j) * j;
        sjw += j * w;
      }
      const double m = static_cast<double>(widths.size());
      const double det = m * sjj - sj * sj;
      const double slope = det > 0.0 ? (m * sjw - sj * sw) / det : 0.0;
      const double offset = (sw - slope * sj) / m;
      const auto width_at = [&](int j) { return offset + slope * j; };
      for (int j = 0; j + 1 < n && ok; ++j) {
        const double ratio = width_at(j) / along[j];
        ok = ratio >= kMinWidthRatio && ratio <= kMaxWidthRatio;
      }
      for (const auto& [j, w] : widths)
        ok = ok && std::abs(w / width_at(j) - 1.0) <= kWidthAgreement;
      // A change at the page border (the background) cannot come before it.
      for (const auto& [j, dist, cells] : open) ok = ok && dist >= (cells - 0.5) * width_at(j);
      if (!ok) continue;
      Placement p;
      p.gy_min = std::min(g0, g_last);
      p.gy_max = std::max(g0, g_last);
      for (int j = 0; j < n; ++j) {
        p.grid.emplace_back(mx, g0 + dir * j);
        p.image.push_back(corners[run[j]].uv_px);
      }
      for (int j = 0; j + 1 < n; ++j) {
        const int r = dir > 0 ? g0 + j : g0 - j - 1;
        for (int s = 0; s < 2; ++s) {
          const Walk& w = rows[j][s];
          if (w.dist_px < 0.0) continue;
          const int sgx = s == 0 ? dir : -dir;
          const double d = std::round(w.dist_px / width_at(j));
          if (d < 1.0 || d > 2.0) continue;  // the page border is not an edge of the print
          p.grid.emplace_back(mx + sgx * d, r + 0.5);
          p.image.push_back(w.crossing_px);
        }
      }
      placements.push_back(std::move(p));
    }
  }
  return placements;
}

// ---- 3. Features from a homography ---------------------------------------------------------

struct Frame {
  const ImageView8& image;
  const ImageF& blurred;
  const Layout& layout;
};

Eigen::Vector2d Map(const Eigen::Matrix3d& H, double gx, double gy) {
  return ApplyHomography(H, Eigen::Vector2d(gx, gy));
}

// Page cell (c, r) lies wholly inside the image, a pixel clear of its border.
bool CellVisible(const Eigen::Matrix3d& H, const ImageF& img, int c, int r) {
  for (int k = 0; k < 4; ++k) {
    const Eigen::Vector2d p = Map(H, c + (k & 1), r + (k >> 1));
    if (!(p.x() >= 1.0 && p.y() >= 1.0 && p.x() <= img.width - 2.0 && p.y() <= img.height - 2.0)) {
      return false;
    }
  }
  return true;
}

// The local cell side at vertex (gx, gy), px (the square root of the image area of a cell
// there, homography.h).
double LocalCellPx(const Eigen::Matrix3d& H, int gx, int gy) {
  return LocalSquareSide(H, Eigen::Vector2d(gx, gy), 1.0);
}

// Edge points of the one-cell segment of a board line from vertex (gx, gy) towards +gy
// (vertical) or +gx (horizontal), when the two cells beside it differ in colour (else none).
// edge_bias_px: the offset of measured edges towards their light side (EdgeBias), removed
// from every point.
std::vector<EdgePoint> SegmentPoints(const Frame& frame, const Eigen::Matrix3d& H, int gx, int gy,
                                     bool vertical, double edge_bias_px = 0.0) {
  std::vector<EdgePoint> points;
  // The cells before (left of / above) and after the segment.
  const int c0 = vertical ? gx - 1 : gx;
  const int r0 = vertical ? gy : gy - 1;
  if (!Layout::OnPage(c0, r0) || !Layout::OnPage(gx, gy)) return points;
  const bool black0 = frame.layout.Black(c0, r0);
  if (black0 == frame.layout.Black(gx, gy)) return points;  // no edge here
  const Eigen::Vector2d s0(gx, gy);
  const Eigen::Vector2d step = vertical ? Eigen::Vector2d(0.0, 1.0) : Eigen::Vector2d(1.0, 0.0);
  // One cell towards the light side, in grid units.
  const Eigen::Vector2d to_light_g =
      (black0 ? 1.0 : -1.0) * (vertical ? Eigen::Vector2d(1.0, 0.0) : Eigen::Vector2d(0.0, 1.0));
  const Eigen::Vector2d a = ApplyHomography(H, s0);
  const Eigen::Vector2d b = ApplyHomography(H, s0 + step);
  const double len_px = (b - a).norm();
  if (!(len_px > 1.0)) return points;
  const Eigen::Vector2d along = (b - a) / len_px;
  // The segment is used between a fifth and four fifths of its length: clear of the blur of
  // the vertices at its ends (where the edge may end, turn or change polarity). About one
  // point per pixel of that part; 3..24 bound the cost.
  constexpr double kFrom = 0.2;
  constexpr double kTo = 0.8;
  const int count = std::clamp(static_cast<int>((kTo - kFrom) * len_px), 3, 24);
  for (int i = 0; i < count; ++i) {
    const Eigen::Vector2d g = s0 + (kFrom + (kTo - kFrom) * (i + 0.5) / count) * step;
    const Eigen::Vector2d q = ApplyHomography(H, g);
    const Eigen::Vector2d to_light = ApplyHomography(H, g + to_light_g) - q;
    Eigen::Vector2d n(-along.y(), along.x());
    if (n.dot(to_light) < 0.0) n = -n;
    // A third of the cell across, within the blur's reach (1..4 px): the parallel edge a
    // cell away stays out of the window.
    const double half_window = std::clamp(0.35 * std::abs(n.dot(to_light)), 1.0, 4.0);
    std::optional<EdgePoint> e = MeasureEdgePoint(frame.image, q, n, half_window);
    if (!e.has_value()) continue;
    e->uv_px -= edge_bias_px * n;
    points.push_back(*e);
  }
  return points;
}

// The edge points of the segments (SegmentPoints) measured under one homography and edge
// bias, each measured once: the lines of neighbouring L-corners share up to three of their
// four segments (the outer vertical lines carry an L-corner on almost every row), which
// made a pass measure most edges several times. One slot per segment starting on the page
// (a flat table, not a map: no node to allocate or tree to walk per lookup).
class SegmentCache {
 public:
  SegmentCache(const Frame& frame, const Eigen::Matrix3d& H, double edge_bias_px)
      : frame_(frame), H_(H), edge_bias_px_(edge_bias_px), slots_(2 * kPageCols * kPageRows) {}

  const std::vector<EdgePoint>& Points(int gx, int gy, bool vertical) {
    // A segment from a vertex off the page's cells has no edge (SegmentPoints).
    if (!Layout::OnPage(gx, gy)) return no_points_;
    std::optional<std::vector<EdgePoint>>& slot =
        slots_[(gy * kPageCols + gx) * 2 + (vertical ? 1 : 0)];
    if (!slot.has_value()) slot = SegmentPoints(frame_, H_, gx, gy, vertical, edge_bias_px_);
    return *slot;
  }

 private:
  const Frame& frame_;
  const Eigen::Matrix3d H_;
  const double edge_bias_px_;
  std::vector<std::optional<std::vector<EdgePoint>>> slots_;
  const std::vector<EdgePoint> no_points_;
};

// Edge points of the board line through vertex (gx, gy), vertical (x = gx) or horizontal
// (y = gy), over the two cells on either side of the vertex: up to four cells of edge, where
// the vertex's own two edges alone would give one each (four times the points against
// noise, a longer base for the direction), short enough for a lens's bending of the line to
// stay negligible.
std::vector<EdgePoint> LinePoints(SegmentCache& segments, int gx, int gy, bool vertical) {
  std::vector<EdgePoint> points;
  for (int k = -2; k < 2; ++k) {
    const std::vector<EdgePoint>& segment =
        vertical ? segments.Points(gx, gy + k, true) : segments.Points(gx + k, gy, false);
    points.insert(points.end(), segment.begin(), segment.end());
  }
  return points;
}

// How far measured edges sit from the true ones towards their light side, px: gamma, a
// sharpening or saturating camera makes a blurred edge's profile asymmetric, and then every
// profile-based edge point is off by a fraction of the blur. The board measures it itself:
// the middle line between two of its X-corners (saddle points, which any monotone grey-level
// response leaves in place) is the true edge, so the offset of its measured edge points from
// the line through the two corners is the bias. uv: the refined features (layout order).
// Returns 0 without two neighbouring X-corners. Cost: like refining two L-corners per pair.
double EdgeBias(const Frame& frame, const Eigen::Matrix3d& H,
                const std::vector<std::optional<Eigen::Vector2d>>& uv) {
  const Layout& layout = frame.layout;
  std::vector<std::optional<Eigen::Vector2d>> x_at(kPageRows + 1);
  for (std::size_t i = 0; i < uv.size(); ++i) {
    const LayoutFeature& f = layout.features[i];
    if (f.kind == FeatureKind::kXCorner && uv[i].has_value()) x_at[f.gy] = uv[i];
  }
  double sum = 0.0;
  double weight = 0.0;
  for (int gy = 0; gy < kPageRows; ++gy) {
    if (!x_at[gy].has_value() || !x_at[gy + 1].has_value()) continue;
    const Eigen::Vector2d a = *x_at[gy];
    const Eigen::Vector2d d = (*x_at[gy + 1] - a).normalized();
    const Eigen::Vector2d normal(-d.y(), d.x());
    // The light side of the segment, as the sign of its offset along `normal`.
    const int c_light =
        layout.Black(layout.middle_gx - 1, gy) ? layout.middle_gx : layout.middle_gx - 1;
    const Eigen::Vector2d light_point =
        ApplyHomography(H, Eigen::Vector2d(c_light + 0.5, gy + 0.5));
    const double sign = normal.dot(light_point - a) >= 0.0 ? 1.0 : -1.0;
    for (const EdgePoint& e : SegmentPoints(frame, H, layout.middle_gx, gy, /*vertical=*/true)) {
      sum += e.weight * sign * normal.dot(e.uv_px - a);
      weight += e.weight;
    }
  }
  return weight > 0.0 ? sum / weight : 0.0;
}

// The refined image position of feature f predicted by H, or nullopt; L-corners from the
// edge points of `segments` (measured under the same H).
std::optional<Eigen::Vector2d> RefineFeature(const Frame& frame, const Eigen::Matrix3d& H,
                                             const LayoutFeature& f, SegmentCache& segments) {
  const Eigen::Vector2d predicted = Map(H, f.gx, f.gy);
  const double side = LocalCellPx(H, f.gx, f.gy);
  std::optional<Eigen::Vector2d> refined;
  if (f.kind == FeatureKind::kXCorner) {
    // A window of a third of the cell (at most 7 px: beyond that the saddle of the blur is
    // flat), as the checker detector.
    SaddleFitOptions saddle;
    saddle.half_window = std::clamp(static_cast<int>(side / 3.0), 2, 7);
    refined = RefineSaddle(frame.blurred, predicted, saddle);
  } else {
    const std::vector<EdgePoint> a = LinePoints(segments, f.gx, f.gy, /*vertical=*/false);
    const std::vector<EdgePoint> b = LinePoints(segments, f.gx, f.gy, /*vertical=*/true);
    // Three points fix a line and show an outlier; fewer means the edge is not there.
    if (a.size() < 3 || b.size() < 3) return std::nullopt;
    const std::optional<Line2d> la = FitWeightedLine(a, Map(H, f.gx + 1, f.gy) - predicted);
    const std::optional<Line2d> lb = FitWeightedLine(b, Map(H, f.gx, f.gy + 1) - predicted);
    if (!la.has_value() || !lb.has_value()) return std::nullopt;
    // The edges are perpendicular on the board; below sin 0.2 (11 degrees) the view is too
    // oblique to intersect them reliably.
    constexpr double kMinSin = 0.2;
    if (std::abs(la->dir.x() * lb->dir.y() - la->dir.y() * lb->dir.x()) < kMinSin) {
      return std::nullopt;
    }
    refined = IntersectLines(*la, *lb);
  }
  if (!refined.has_value() || (*refined - predicted).norm() > kMaxPredictionCellFraction * side) {
    return std::nullopt;
  }
  return refined;
}

// The mean of the blurred image over a cross of points around the centre of page cell
// (c, r) (a quarter cell out: averages noise, stays inside the cell).
double CellValue(const ImageF& blurred, const Eigen::Matrix3d& H, int c, int r) {
  constexpr std::array<std::array<double, 2>, 5> kOffsets = {
      {{0.0, 0.0}, {0.25, 0.0}, {-0.25, 0.0}, {0.0, 0.25}, {0.0, -0.25}}};
  double sum = 0.0;
  for (const auto& o : kOffsets) {
    const Eigen::Vector2d uv = Map(H, c + 0.5 + o[0], r + 0.5 + o[1]);
    sum += SampleBilinear(blurred, uv.x(), uv.y());
  }
  return sum / kOffsets.size();
}

enum class CellState : std::uint8_t { kHidden, kOk, kWrong };

struct BoardFit {
  bool ok = false;
  DetectReason failure = DetectReason::kVerificationFailed;
  std::vector<std::optional<Eigen::Vector2d>> uv;  // per feature (layout order), certain ones
  int certain = 0;
};

// Checks the colours of every visible page cell through H against the code; fills states.
// False when a visible cell has the wrong colour.
bool CheckCells(const Frame& frame, const Eigen::Matrix3d& H, double min_contrast,
                double margin_fraction,
                std::array<std::array<CellState, kPageCols>, kPageRows>* states) {
  const Layout& layout = frame.layout;
  const int mx = layout.middle_gx;
  std::array<std::array<double, kPageCols>, kPageRows> value{};
  std::array<std::array<bool, kPageCols>, kPageRows> visible{};
  for (int r = 0; r < kPageRows; ++r) {
    for (int c = 0; c < kPageCols; ++c) {
      visible[r][c] = CellVisible(H, frame.blurred, c, r);
      if (visible[r][c]) value[r][c] = CellValue(frame.blurred, H, c, r);
      (*states)[r][c] = CellState::kHidden;
    }
  }
  // Per row, the threshold halfway between the two cells beside the middle line (one black,
  // one white in every row of the pattern); the margin rows borrow their neighbour's.
  std::array<std::optional<std::pair<double, double>>, kPageRows> level;  // threshold, contrast
  for (int r = 0; r < kPageRows; ++r) {
    const int c_dark = layout.Black(mx - 1, r) ? mx - 1 : mx;
    const int c_light = c_dark == mx ? mx - 1 : mx;
    if (layout.Black(c_light, r) || !layout.Black(c_dark, r)) continue;  // a margin row
    if (!visible[r][c_dark] || !visible[r][c_light]) continue;
    const double contrast = value[r][c_light] - value[r][c_dark];
    if (contrast < min_contrast) return false;
    level[r] = std::make_pair(0.5 * (value[r][c_light] + value[r][c_dark]), contrast);
  }
  for (int r = 0; r < kPageRows; ++r) {
    if (level[r].has_value()) continue;
    if (r > 0 && level[r - 1].has_value() && !layout.Black(mx, r) && !layout.Black(mx - 1, r)) {
      level[r] = level[r - 1];
    } else if (r + 1 < kPageRows && level[r + 1].has_value() && !layout.Black(mx, r) &&
               !layout.Black(mx - 1, r)) {
      level[r] = level[r + 1];
    }
  }
  for (int r = 0; r < kPageRows; ++r) {
    if (!level[r].has_value()) continue;
    const auto [threshold, contrast] = *level[r];
    for (int c = 0; c < kPageCols; ++c) {
      if (!visible[r][c]) continue;
      const double signed_margin =
          (layout.Black(c, r) ? threshold - value[r][c] : value[r][c] - threshold) / contrast;
      if (signed_margin < margin_fraction) return false;
      (*states)[r][c] = CellState::kOk;
    }
  }
  return true;
}

// True when another placement of the code (shifted along the board, or turned by 180
// degrees) explains every verified cell as well: then the position is not decoded uniquely.
bool PlacementAmbiguous(const Layout& layout,
                        const std::array<std::array<CellState, kPageCols>, kPageRows>& states) {
  for (int turned = 0; turned < 2; ++turned) {
    for (int shift = -kPageRows; shift <= kPageRows; ++shift) {
      if (turned == 0 && shift == 0) continue;
      bool fits = true;
      int compared = 0;
      for (int r = 0; r < kPageRows && fits; ++r) {
        for (int c = 0; c < kPageCols && fits; ++c) {
          if (states[r][c] != CellState::kOk) continue;
          const int c2 = turned ? kPageCols - 1 - c : c;
          const int r2 = (turned ? kPageRows - 1 - r : r) + shift;
          fits = Layout::OnPage(c2, r2) && layout.Black(c2, r2) == layout.Black(c, r);
          ++compared;
        }
      }
      if (fits && compared > 0) return true;
    }
  }
  return false;
}

// Grows the board from a placement: predict, refine, refit, a few rows further each round;
// then the final refinement, residual and colour checks.
BoardFit FitBoard(const Frame& frame, const Placement& seed, const VerticalOptions& options) {
  BoardFit fit;
  const Layout& layout = frame.layout;
  const int nf = static_cast<int>(layout.features.size());
  fit.uv.assign(nf, std::nullopt);
  std::optional<HomographyFit> h = FitHomography(seed.grid, seed.image);
  if (!h.has_value()) return fit;
  int lo = seed.gy_min;
  int hi = seed.gy_max;
  const auto refit = [&]() {
    std::vector<Eigen::Vector2d> g, uv;
    for (int i = 0; i < nf; ++i) {
      if (!fit.uv[i].has_value()) continue;
      g.emplace_back(layout.features[i].gx, layout.features[i].gy);
      uv.push_back(*fit.uv[i]);
    }
    return FitHomography(g, uv);
  };
  const auto feature_visible = [&](const Eigen::Matrix3d& H, const LayoutFeature& f) {
    for (int k = 0; k < 4; ++k) {
      if (!CellVisible(H, frame.blurred, f.gx - 1 + (k & 1), f.gy - 1 + (k >> 1))) return false;
    }
    return true;
  };
  // Each round reaches two vertex rows beyond the features found so far: the homography of
  // a few rows extrapolates that far within a fraction of a cell. 20 rounds cover the
  // board from any run.
  constexpr int kGrowRows = 2;
  for (int round = 0; round < kPageRows; ++round) {
    int added = 0;
    SegmentCache segments(frame, h->H, /*edge_bias_px=*/0.0);
    for (int i = 0; i < nf; ++i) {
      const LayoutFeature& f = layout.features[i];
      if (fit.uv[i].has_value() || f.gy < lo - kGrowRows || f.gy > hi + kGrowRows) continue;
      if (!feature_visible(h->H, f)) continue;
      fit.uv[i] = RefineFeature(frame, h->H, f, segments);
      if (fit.uv[i].has_value()) {
        ++added;
        lo = std::min(lo, f.gy);
        hi = std::max(hi, f.gy);
      }
    }
    if (added == 0 && round > 0) break;
    std::optional<HomographyFit> next = refit();
    if (!next.has_value()) return fit;
    h = next;
    if (added == 0) break;
  }
  // Final pass: every feature again from the final homography (windows centred on the
  // true edges), then the residual check against the refitted homography.
  const double edge_bias_px = EdgeBias(frame, h->H, fit.uv);
  for (int pass = 0; pass < 2; ++pass) {
    SegmentCache segments(frame, h->H, edge_bias_px);
    for (int i = 0; i < nf; ++i) {
      if (fit.uv[i].has_value()) {
        fit.uv[i] = RefineFeature(frame, h->H, layout.features[i], segments);
      }
    }
    std::optional<HomographyFit> next = refit();
    if (!next.has_value()) return fit;
    h = next;
    if (pass == 1) break;
    // Drop the features off the homography by more than the residual bound, then refit.
    for (int i = 0; i < nf; ++i) {
      if (!fit.uv[i].has_value()) continue;
      const LayoutFeature& f = layout.features[i];
      const double tol = options.max_residual_cell_fraction * LocalCellPx(h->H, f.gx, f.gy);
      if ((Map(h->H, f.gx, f.gy) - *fit.uv[i]).norm() > tol) fit.uv[i].reset();
    }
    next = refit();
    if (!next.has_value()) return fit;
    h = next;
  }
  std::array<std::array<CellState, kPageCols>, kPageRows> states;
  if (!CheckCells(frame, h->H, 0.5 * options.corners.min_contrast, options.min_cell_margin_fraction,
                  &states)) {
    return fit;
  }
  for (int i = 0; i < nf; ++i) {
    if (!fit.uv[i].has_value()) continue;
    const LayoutFeature& f = layout.features[i];
    const double tol = options.max_residual_cell_fraction * LocalCellPx(h->H, f.gx, f.gy);
    bool certain = (Map(h->H, f.gx, f.gy) - *fit.uv[i]).norm() <= tol;
    for (int k = 0; k < 4 && certain; ++k) {
      certain = states[f.gy - 1 + (k >> 1)][f.gx - 1 + (k & 1)] == CellState::kOk;
    }
    if (!certain) fit.uv[i].reset();
    fit.certain += certain ? 1 : 0;
  }
  if (PlacementAmbiguous(layout, states)) {
    fit.failure = DetectReason::kAmbiguous;
    return fit;
  }
  // A partial view reports its features only when they are at least a run's worth.
  if (fit.certain < options.min_chain_corners) {
    fit.failure = DetectReason::kTooFewFeatures;
    return fit;
  }
  fit.ok = true;
  return fit;
}

// The outcome of steps 1-5 on one pyramid level: failure kNone and the board's fit (its
// positions in the level's pixels), or the reason no single board was found.
struct LevelSearch {
  DetectReason failure = DetectReason::kTooFewFeatures;
  BoardFit fit;
};

// Steps 1-5 of the header's method on `view` (the image or one of its halvings): runs of
// X-corners, their placements on the code, and the verified boards grown from them; two
// boards that disagree are kAmbiguous.
LevelSearch SearchLevel(const ImageView8& view, const Layout& layout,
                        const VerticalOptions& options) {
  LevelSearch search;
  const ImageF blurred = GaussianBlur(view, options.blur_sigma_px);
  const std::vector<XCorner> corners = FindXCorners(blurred, options.corners);
  if (corners.empty()) {
    search.failure = DetectReason::kNoCandidates;
    return search;
  }
  int max_run = 0;
  for (bool x : layout.x_corner_at_gy) max_run += x ? 1 : 0;
  const std::vector<std::vector<int>> runs =
      StraightRuns(corners, LinkXCorners(corners), options.min_chain_corners, max_run);
  const Frame frame{view, blurred, layout};
  DetectReason failure = DetectReason::kTooFewFeatures;
  std::vector<BoardFit> fits;
  std::vector<std::array<Walk, 2>> rows;
  std::vector<double> along;
  for (const std::vector<int>& run : runs) {
    // A run whose corners a board found already holds is that board again.
    bool known = false;
    for (const BoardFit& f : fits) {
      for (const auto& uv : f.uv) {
        known = known || (uv.has_value() && (*uv - corners[run.front()].uv_px).norm() < 1.0);
      }
    }
    if (known) continue;
    if (!WalkRows(blurred, corners, run, options.corners.min_contrast, &rows, &along)) continue;
    for (const Placement& placement : PlaceRun(layout, corners, run, rows, along)) {
      BoardFit fit = FitBoard(frame, placement, options);
      if (fit.ok) {
        fits.push_back(std::move(fit));
      } else if (fit.failure == DetectReason::kAmbiguous ||
                 failure == DetectReason::kTooFewFeatures) {
        failure = fit.failure;
      }
    }
  }
  if (fits.empty()) {
    search.failure = failure;
    return search;
  }
  // Two verified boards that do not share features at the same places: two boards in view,
  // or one board placed two ways (then some id sits at two places).
  for (std::size_t k = 1; k < fits.size(); ++k) {
    int common = 0;
    for (std::size_t i = 0; i < fits[0].uv.size(); ++i) {
      const auto& a = fits[0].uv[i];
      const auto& b = fits[k].uv[i];
      if (!a.has_value() || !b.has_value()) continue;
      ++common;
      // 1 px: far above the refinement's scatter, far below a cell.
      if ((*a - *b).norm() > 1.0) common = -1000000;
    }
    if (common <= 0) {
      search.failure = DetectReason::kAmbiguous;
      return search;
    }
  }
  search.failure = DetectReason::kNone;
  search.fit = std::move(fits.front());
  return search;
}

// The board found on pyramid level `level` (its fit in that level's pixels) fitted again at
// full resolution: FitBoard seeded with its features, on the part of the image that holds
// the page (blurred alone: a fraction of the image's cost). The crop keeps the blur's
// clamped border a kernel away from the page, and its own border is the image's wherever
// the page reaches that, so every cell, edge and window FitBoard looks at is as on the
// whole image. A fit that fails at full resolution is returned with ok = false.
BoardFit RefineAtFullResolution(const ImageView8& image, const Layout& layout,
                                const BoardFit& coarse, int level, const VerticalOptions& options) {
  BoardFit failed;
  Placement seed;
  seed.gy_min = kPageRows;
  seed.gy_max = 0;
  for (std::size_t i = 0; i < coarse.uv.size(); ++i) {
    if (!coarse.uv[i].has_value()) continue;
    const LayoutFeature& f = layout.features[i];
    seed.grid.emplace_back(f.gx, f.gy);
    seed.image.push_back(LevelToImage(*coarse.uv[i], level));
    seed.gy_min = std::min(seed.gy_min, f.gy);
    seed.gy_max = std::max(seed.gy_max, f.gy);
  }
  const std::optional<HomographyFit> h = FitHomography(seed.grid, seed.image);
  if (!h.has_value()) return failed;
  Eigen::AlignedBox2d page;
  for (int k = 0; k < 4; ++k) page.extend(Map(h->H, (k & 1) * kPageCols, (k >> 1) * kPageRows));
  // The blur kernel (3 sigma) and two pixels of rounding clear of the page.
  const double pad = std::ceil(3.0 * options.blur_sigma_px) + 2.0;
  if (!page.min().allFinite() || !page.max().allFinite()) return failed;
  const int x0 =
      static_cast<int>(std::clamp(std::floor(page.min().x() - pad), 0.0, image.width - 1.0));
  const int y0 =
      static_cast<int>(std::clamp(std::floor(page.min().y() - pad), 0.0, image.height - 1.0));
  const int x1 =
      static_cast<int>(std::clamp(std::ceil(page.max().x() + pad), 0.0, image.width - 1.0));
  const int y1 =
      static_cast<int>(std::clamp(std::ceil(page.max().y() + pad), 0.0, image.height - 1.0));
  // FitBoard's smallest use: a saddle window and its border rule.
  constexpr int kMinCropPx = 16;
  if (x1 - x0 + 1 < kMinCropPx || y1 - y0 + 1 < kMinCropPx) return failed;
  ImageView8 crop = image;
  crop.data = image.Row(y0) + x0;
  crop.width = x1 - x0 + 1;
  crop.height = y1 - y0 + 1;
  const Eigen::Vector2d origin(x0, y0);
  for (Eigen::Vector2d& uv : seed.image) uv -= origin;
  const ImageF blurred = GaussianBlur(crop, options.blur_sigma_px);
  BoardFit fit = FitBoard(Frame{crop, blurred, layout}, seed, options);
  for (auto& uv : fit.uv) {
    if (uv.has_value()) *uv += origin;
  }
  return fit;
}

}  // namespace

std::string_view VerticalOptions::Validate() const {
  if (!(blur_sigma_px >= 0.5 && blur_sigma_px <= 4.0)) return "blur_sigma_px";
  if (const std::string_view bad = corners.Validate(); !bad.empty()) return bad;
  if (min_chain_corners < 3 || min_chain_corners > 17) return "min_chain_corners";
  if (!(max_residual_cell_fraction > 0.0 && max_residual_cell_fraction <= 0.5)) {
    return "max_residual_cell_fraction";
  }
  if (!(min_cell_margin_fraction > 0.0 && min_cell_margin_fraction < 0.5)) {
    return "min_cell_margin_fraction";
  }
  return {};
}

Detection DetectVertical(const ImageView8& image, const Board& board,
                         const VerticalOptions& options) {
  Detection result;
  result.reason =
      CheckDetectorInput(image, board, BoardType::kVertical, options.Validate().empty());
  if (result.reason != DetectReason::kNone) return result;
  // The raw range bounds the blurred one: an image without min_contrast anywhere has no
  // corner.
  if (GreyRange(image) < options.corners.min_contrast) {
    result.reason = DetectReason::kLowContrast;
    return result;
  }
  const Layout layout = MakeLayout(board);
  // Coarse to fine (x_corners.h, kMinCoarseLevelSidePx): the search on each halving of the
  // image from the coarsest, then on the image itself, until a level finds one board; a
  // board found coarse is fitted again at full resolution (RefineAtFullResolution), so it
  // is as accurate as one found on the image. Anything else on a coarse level (nothing,
  // two boards, or a fit that fails at full resolution) passes on to the finer levels, so
  // the image itself decides, with the reason reported without the coarse levels; boards
  // too small for the coarse levels pay for them on top (at most a third more).
  const std::vector<Image8> pyramid = HalvingPyramid(image, kMinCoarseLevelSidePx);
  for (int level = static_cast<int>(pyramid.size()); level >= 0; --level) {
    LevelSearch search =
        SearchLevel(level == 0 ? image : pyramid[level - 1].view(), layout, options);
    result.reason = search.failure;
    if (search.failure != DetectReason::kNone) continue;
    if (level > 0) {
      search.fit = RefineAtFullResolution(image, layout, search.fit, level, options);
      if (!search.fit.ok) continue;
    }
    const BoardFit& best = search.fit;
    for (std::size_t i = 0; i < best.uv.size(); ++i) {
      if (!best.uv[i].has_value()) continue;
      const BoardFeature& bf = board.features()[layout.features[i].id];
      DetectedFeature f;
      f.id = bf.id;
      f.uv_px = *best.uv[i];
      f.p_board = bf.p_board;
      f.marker = bf.marker;
      result.features.push_back(f);
    }
    result.found = best.certain == static_cast<int>(layout.features.size());
    result.reason = result.found ? DetectReason::kNone : DetectReason::kPartial;
    return result;
  }
  return result;
}

}  // namespace linecal
