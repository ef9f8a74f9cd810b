#include "detectors/chessboard/chessboard_detector.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <numbers>
#include <optional>
#include <span>
#include <vector>

#include "detectors/common/binarise.h"
#include "detectors/common/contours.h"
#include "detectors/common/corner_refine.h"
#include "detectors/common/edge_lines.h"
#include "detectors/common/homography.h"
#include "detectors/common/image_filters.h"
#include "detectors/common/paint_check.h"
#include "detectors/common/x_corners.h"

namespace linecal {
namespace {

// ---- The board model, derived from Board (so a scaled board works unchanged) -------------

// One side of a black square on a board edge line.
struct Segment {
  Eigen::Vector2d a_board = Eigen::Vector2d::Zero();
  Eigen::Vector2d b_board = Eigen::Vector2d::Zero();
  Eigen::Vector2d light_normal_board = Eigen::Vector2d::Zero();  // unit, towards the white
};

// A straight edge of one group: the sides of its squares on one board line.
struct EdgeLine {
  int group = 0;
  bool horizontal = true;  // y = coord, else x = coord (board frame)
  double coord = 0.0;
  std::vector<Segment> segments;
};

// A group in its local grid: the middle square is [0, 1]^2 with the corners it shares
// with its two neighbours at (0, 0) and (1, 0) (the first neighbour's square is
// [-1, 0] x [-1, 0], the second's [1, 2] x [-1, 0]); axes handed like the image's (u right,
// v down) for a camera facing the print. Board point = origin + gx step + gy R(step), R
// the clockwise quarter turn as seen facing the print.
struct GroupModel {
  Eigen::Vector2d origin_board = Eigen::Vector2d::Zero();
  Eigen::Vector2d step_board = Eigen::Vector2d::Zero();

  Eigen::Vector2d ToBoard(const Eigen::Vector2d& g) const {
    const Eigen::Vector2d turned(step_board.y(), -step_board.x());
    return origin_board + g.x() * step_board + g.y() * turned;
  }
};

struct FeatureModel {
  int h_line = -1;  // the EdgeLine indices through the feature
  int v_line = -1;
  bool x_corner = false;
};

struct ChessModel {
  std::array<GroupModel, 2> groups;  // left (smaller board x) first
  std::vector<EdgeLine> lines;
  std::vector<FeatureModel> features;  // by feature id
  double square_m = 0.0;
};

// Corners of a black square, clockwise as seen facing the print (y up): TL, TR, BR, BL.
std::array<Eigen::Vector2d, 4> BoxCorners(const Eigen::AlignedBox2d& b) {
  return {Eigen::Vector2d(b.min().x(), b.max().y()), b.max(),
          Eigen::Vector2d(b.max().x(), b.min().y()), b.min()};
}

// The model of a board made of groups of three squares (docs/boards.md §1); nullopt when the
// board is not such a board (two groups, every feature on one vertical and one horizontal
// edge line of its group, every X-corner on one horizontal board line) or is not symmetric
// under 180 degrees (see the header).
std::optional<ChessModel> MakeModel(const Board& board) {
  std::vector<Eigen::AlignedBox2d> squares;
  for (const BoardShape& s : board.shapes()) {
    if (s.geometry == ShapeGeometry::kRect && s.paint == Paint::kBlack) {
      squares.push_back(s.box_board);
    }
  }
  if (squares.empty()) return std::nullopt;
  ChessModel m;
  m.square_m = squares[0].sizes().x();
  // Coordinates are exact multiples of the PDF unit; a micrometre (times the scale) is far
  // below any printed detail and far above rounding.
  const double eps = 1e-6 * board.params().scale;
  const auto same = [eps](const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
    return (a - b).norm() < eps;
  };
  // 180-degree symmetry: every square's image under p -> -p is a square.
  for (const Eigen::AlignedBox2d& s : squares) {
    if (std::none_of(squares.begin(), squares.end(), [&](const Eigen::AlignedBox2d& o) {
          return same(o.min(), -s.max()) && same(o.max(), -s.min());
        })) {
      return std::nullopt;
    }
  }
  std::vector<int> group_of(squares.size(), -1);
  std::vector<std::pair<double, GroupModel>> groups;  // centre x, model
  std::vector<std::array<int, 3>> members;
  for (std::size_t i = 0; i < squares.size(); ++i) {
    const std::array<Eigen::Vector2d, 4> ci = BoxCorners(squares[i]);
    std::array<int, 4> touching = {-1, -1, -1, -1};  // per corner of i, the square there
    int count = 0;
    for (std::size_t j = 0; j < squares.size(); ++j) {
      if (j == i) continue;
      for (int k = 0; k < 4; ++k) {
        for (const Eigen::Vector2d& cj : BoxCorners(squares[j])) {
          if (same(ci[k], cj)) {
            touching[k] = static_cast<int>(j);
            ++count;
          }
        }
      }
    }
    if (count != 2) continue;
    for (int k = 0; k < 4; ++k) {
      const int next = (k + 1) % 4;
      if (touching[k] < 0 || touching[next] < 0) continue;
      GroupModel g;
      g.origin_board = ci[k];
      g.step_board = ci[next] - ci[k];
      groups.emplace_back(squares[i].center().x(), g);
      members.push_back({static_cast<int>(i), touching[k], touching[next]});
    }
  }
  if (groups.size() != 2) return std::nullopt;
  const int left = groups[0].first < groups[1].first ? 0 : 1;
  m.groups = {groups[left].second, groups[1 - left].second};
  for (int g = 0; g < 2; ++g) {
    for (int s : members[g == 0 ? left : 1 - left]) group_of[s] = g;
  }
  // Edge lines: the four sides of each square, grouped by (group, orientation, coordinate).
  for (std::size_t i = 0; i < squares.size(); ++i) {
    if (group_of[i] < 0) return std::nullopt;
    const std::array<Eigen::Vector2d, 4> c = BoxCorners(squares[i]);
    // Side k runs from corner k to k + 1: top, right, bottom, left.
    const std::array<Eigen::Vector2d, 4> normals = {Eigen::Vector2d(0, 1), Eigen::Vector2d(1, 0),
                                                    Eigen::Vector2d(0, -1), Eigen::Vector2d(-1, 0)};
    for (int k = 0; k < 4; ++k) {
      const bool horizontal = k % 2 == 0;
      const double coord = horizontal ? c[k].y() : c[k].x();
      auto it = std::find_if(m.lines.begin(), m.lines.end(), [&](const EdgeLine& l) {
        return l.group == group_of[i] && l.horizontal == horizontal &&
               std::abs(l.coord - coord) < eps;
      });
      if (it == m.lines.end()) {
        m.lines.push_back({group_of[i], horizontal, coord, {}});
        it = m.lines.end() - 1;
      }
      it->segments.push_back({c[k], c[(k + 1) % 4], normals[k]});
    }
  }
  for (const BoardFeature& f : board.features()) {
    FeatureModel fm;
    fm.x_corner = f.kind == FeatureKind::kXCorner;
    for (std::size_t l = 0; l < m.lines.size(); ++l) {
      const EdgeLine& line = m.lines[l];
      const double v = line.horizontal ? f.p_board.y() : f.p_board.x();
      if (std::abs(v - line.coord) >= eps) continue;
      for (const Segment& s : line.segments) {
        if (same(s.a_board, f.p_board) || same(s.b_board, f.p_board)) {
          (line.horizontal ? fm.h_line : fm.v_line) = static_cast<int>(l);
        }
      }
    }
    if (fm.h_line < 0 || fm.v_line < 0) return std::nullopt;
    m.features.push_back(fm);
  }
  // The second path's gate (OnOneLine): every X-corner on one horizontal board line.
  std::optional<double> x_line_y;
  for (const FeatureModel& fm : m.features) {
    if (!fm.x_corner) continue;
    const double y = m.lines[fm.h_line].coord;
    if (x_line_y && std::abs(*x_line_y - y) >= eps) return std::nullopt;
    x_line_y = y;
  }
  return m;
}

// ---- Candidates: square quads, touching pairs, groups of three ---------------------------

struct SquareQuad {
  std::array<Eigen::Vector2d, 4> corners_px;  // clockwise in the image
  Eigen::Vector2d centre_px = Eigen::Vector2d::Zero();
  double side_px = 0.0;  // mean side length
  int component = 0;     // index into the labelling's components
};

struct Touch {
  int other = 0;         // the other quad
  int corner = 0;        // this quad's corner at the shared vertex
  int other_corner = 0;  // the other quad's corner there
};

// A group seen in the image: quads (middle, first neighbour, second neighbour) and, for
// each, its corner at local grid corner 0 of its square (see kLocal).
struct Triple {
  std::array<int, 3> quads = {0, 0, 0};
  std::array<int, 3> first_corner = {0, 0, 0};
  double side_px = 0.0;
};

// Local grid positions (GroupModel) of the quads' corners, in their clockwise order from
// first_corner: the middle square from its corner shared with the first neighbour, the
// neighbours from their shared corners.
constexpr double kLocal[3][4][2] = {{{0, 0}, {1, 0}, {1, 1}, {0, 1}},
                                    {{0, 0}, {-1, 0}, {-1, -1}, {0, -1}},
                                    {{1, 0}, {1, -1}, {2, -1}, {2, 0}}};

// The 12 image corners of a triple and their local grid positions.
void TriplePoints(const Triple& t, const std::vector<SquareQuad>& quads,
                  std::vector<Eigen::Vector2d>* local, std::vector<Eigen::Vector2d>* image) {
  for (int m = 0; m < 3; ++m) {
    for (int r = 0; r < 4; ++r) {
      local->emplace_back(kLocal[m][r][0], kLocal[m][r][1]);
      image->push_back(quads[t.quads[m]].corners_px[(t.first_corner[m] + r) % 4]);
    }
  }
}

// The coarse homography tolerance for contour corners of squares of side_px: a fraction of
// the side, plus a pixel for the contour's pixel steps.
double CoarseTolerancePx(const ChessboardOptions& options, double side_px) {
  return options.coarse_residual_fraction * side_px + 1.0;
}

std::vector<Triple> FindTriples(const std::vector<SquareQuad>& quads,
                                const ChessboardOptions& options) {
  const int n = static_cast<int>(quads.size());
  std::vector<std::vector<Touch>> touches(n);
  for (int i = 0; i < n; ++i) {
    for (int j = i + 1; j < n; ++j) {
      const SquareQuad& a = quads[i];
      const SquareQuad& b = quads[j];
      // Squares of one group differ in size only by perspective over two squares: a factor
      // of 2 is far beyond any view of docs/acceptance.md.
      const double small = std::min(a.side_px, b.side_px);
      const double large = std::max(a.side_px, b.side_px);
      if (large > 2.0 * small) continue;
      // Centres of touching squares are sqrt(2) sides apart (more under perspective).
      if ((a.centre_px - b.centre_px).squaredNorm() > 6.25 * large * large) continue;
      int best_a = 0, best_b = 0;
      double best = 1e300;
      for (int ka = 0; ka < 4; ++ka) {
        for (int kb = 0; kb < 4; ++kb) {
          const double d = (a.corners_px[ka] - b.corners_px[kb]).norm();
          if (d < best) {
            best = d;
            best_a = ka;
            best_b = kb;
          }
        }
      }
      // The contour of each square retreats from the shared vertex by about the blur over
      // the sine of half the corner's angle (acute under perspective): the corners may lie
      // well apart, and the reflection test below is the sharp one.
      if (best > 2.0 * options.touch_fraction * small + 2.0) continue;
      const Eigen::Vector2d vertex = 0.5 * (a.corners_px[best_a] + b.corners_px[best_b]);
      const Eigen::Vector2d mirrored = 2.0 * vertex - a.centre_px;
      if ((mirrored - b.centre_px).norm() > options.touch_fraction * 0.5 * (small + large)) {
        continue;
      }
      touches[i].push_back({j, best_a, best_b});
      touches[j].push_back({i, best_b, best_a});
    }
  }
  std::vector<Triple> triples;
  std::vector<Eigen::Vector2d> local, image;
  HomographyFitOptions dlt;
  dlt.refine = false;  // a coarse check: contour corners are off by a pixel anyway
  for (int m = 0; m < n; ++m) {
    for (const Touch& t1 : touches[m]) {
      for (const Touch& t2 : touches[m]) {
        if (t2.corner != (t1.corner + 1) % 4 || t1.other == t2.other) continue;
        Triple t;
        t.quads = {m, t1.other, t2.other};
        t.first_corner = {t1.corner, t1.other_corner, t2.other_corner};
        t.side_px = (quads[m].side_px + quads[t1.other].side_px + quads[t2.other].side_px) / 3.0;
        local.clear();
        image.clear();
        TriplePoints(t, quads, &local, &image);
        const std::optional<HomographyFit> fit = FitHomography(local, image, dlt);
        if (!fit || fit->max_residual > CoarseTolerancePx(options, t.side_px)) continue;
        triples.push_back(t);
      }
    }
  }
  return triples;
}

// ---- Sub-pixel refinement ---------------------------------------------------------------

// Saddle fit of an X-corner: blur sigma and window as the checker detector's (sigma 1.5
// px keeps the saddle stable under noise of sigma 6 and is small enough for 12 px
// squares; the window is a third of the local square side, 2..7 px).
constexpr double kSaddleBlurSigmaPx = 1.5;

// Edge points keep this far from the ends of a side (at least a tenth of it, at most 0.35):
// near a vertex the window across the edge also sees the blurred perpendicular side or
// the neighbour's corner, which pulls the point towards it. 3 px is the window of half
// the edge (up to 4 px across) seen from the perpendicular side at the blur of
// docs/acceptance.md (1.5 px at most).
constexpr double kEdgeEndMarginPx = 3.0;

// The edge points of one edge line, each with the unit image normal of its segment towards
// the white, and the line's direction hint (FitWeightedLine's `towards`).
struct MeasuredLine {
  std::vector<EdgePoint> points;
  std::vector<Eigen::Vector2d> light_normals;
  Eigen::Vector2d hint = Eigen::Vector2d::Zero();
};

// The edge points of each edge line, measured around its prediction by H_image_board.
std::optional<std::vector<MeasuredLine>> MeasureEdges(const ImageView8& image,
                                                      const ChessModel& model,
                                                      const Eigen::Matrix3d& H) {
  std::vector<MeasuredLine> lines;
  for (const EdgeLine& line : model.lines) {
    MeasuredLine m;
    Eigen::Vector2d& hint = m.hint;
    for (const Segment& s : line.segments) {
      const Eigen::Vector2d a = ApplyHomography(H, s.a_board);
      const Eigen::Vector2d b = ApplyHomography(H, s.b_board);
      const double len = (b - a).norm();
      if (!(len > 1.0)) return std::nullopt;
      const Eigen::Vector2d tangent = (b - a) / len;
      if (hint.dot(tangent) < 0.0) {
        hint -= tangent;
      } else {
        hint += tangent;
      }
      const Eigen::Vector2d mid_board = 0.5 * (s.a_board + s.b_board);
      const Eigen::Vector2d mid = ApplyHomography(H, mid_board);
      Eigen::Vector2d normal(-tangent.y(), tangent.x());
      const Eigen::Vector2d light =
          ApplyHomography(H, mid_board + 0.25 * model.square_m * s.light_normal_board);
      if (normal.dot(light - mid) < 0.0) normal = -normal;
      // The window stays within 0.3 of the square across the edge: the nearest edge of the
      // same polarity is beyond the white margin (two thirds of a square) or the square's
      // far side; at most 4 px, beyond which only the blur's tail is seen.
      const double across_px =
          (ApplyHomography(H, mid_board - model.square_m * s.light_normal_board) - mid).norm();
      const double half_window_px = std::clamp(0.3 * across_px, 1.0, 4.0);
      // About one edge point per pixel of side, at least 8 (a line from few points is
      // noisy), at most 80 (more points add little).
      const int samples = std::clamp(static_cast<int>(len), 8, 80);
      const double end = std::clamp(kEdgeEndMarginPx / len, 0.1, 0.35);
      for (int i = 0; i < samples; ++i) {
        const double t = end + (1.0 - 2.0 * end) * (i + 0.5) / samples;
        const Eigen::Vector2d q = ApplyHomography(H, s.a_board + t * (s.b_board - s.a_board));
        if (!q.allFinite()) return std::nullopt;
        const std::optional<EdgePoint> e = MeasureEdgePoint(image, q, normal, half_window_px);
        if (e) {
          m.points.push_back(*e);
          m.light_normals.push_back(normal);
        }
      }
    }
    // A line from fewer points than a side's minimum of 8 is not trusted.
    if (m.points.size() < 8) return std::nullopt;
    lines.push_back(std::move(m));
  }
  return lines;
}

// The line fitted to a measured edge line's points, each first moved by bias_px along its
// light normal (EdgeBiasPx: the edge locator's shift, undone): the total-least-squares line,
// or, when `direction` is given, the line of that direction through the points' weighted
// centroid. nullopt as FitWeightedLine.
std::optional<Line2d> FitEdgeLine(const MeasuredLine& line, double bias_px,
                                  const std::optional<Eigen::Vector2d>& direction) {
  std::vector<EdgePoint> points = line.points;
  for (std::size_t i = 0; i < points.size(); ++i) {
    points[i].uv_px -= bias_px * line.light_normals[i];
  }
  if (!direction) return FitWeightedLine(points, line.hint);
  Line2d fit;
  double weight = 0.0;
  for (const EdgePoint& e : points) {
    fit.point += e.weight * e.uv_px;
    weight += e.weight;
  }
  if (!(weight > 0.0)) return std::nullopt;
  fit.point /= weight;
  fit.dir = direction->dot(line.hint) < 0.0 ? Eigen::Vector2d(-*direction) : *direction;
  return fit;
}

// The shift of the edge locator along the light normal, pixels (positive: edges seen
// towards the white), common to the edges of one group (one print, one blur, one gamma):
// any asymmetry of the edge profile (gamma, the blur's tail) moves every edge point of the
// group that way. A line whose segments have both polarities (those through the
// X-corners: their segments alternate at the vertex) shows the shift as an offset between
// its two polarities; left uncorrected it turns the line about the vertex and moves the
// L-corners at its ends by more than the shift. Linear least squares over the group's
// lines of the points' distances from their fitted lines (`fitted`, by line) in an offset
// and a turn per line plus the common shift times the light normal's sign; 0 when no line
// has both polarities. O(points).
double EdgeBiasPx(const ChessModel& model, int group, const std::vector<MeasuredLine>& measured,
                  const std::vector<Line2d>& fitted) {
  double num = 0.0, den = 0.0, total = 0.0;
  for (std::size_t l = 0; l < measured.size(); ++l) {
    if (model.lines[l].group != group) continue;
    const MeasuredLine& m = measured[l];
    const Line2d& line = fitted[l];
    const Eigen::Vector2d n(-line.dir.y(), line.dir.x());
    // Per point: along-line position t, distance r, polarity s; weighted normal equations
    // of [1 t] to eliminate the line's own offset and turn from s and r.
    Eigen::Matrix2d xtx = Eigen::Matrix2d::Zero();
    Eigen::Vector2d xts = Eigen::Vector2d::Zero(), xtr = Eigen::Vector2d::Zero();
    double sts = 0.0, str = 0.0;
    for (std::size_t i = 0; i < m.points.size(); ++i) {
      const Eigen::Vector2d d = m.points[i].uv_px - line.point;
      const Eigen::Vector2d x(1.0, line.dir.dot(d));
      const double r = n.dot(d);
      const double sgn = n.dot(m.light_normals[i]);
      const double w = m.points[i].weight;
      xtx += w * x * x.transpose();
      xts += w * sgn * x;
      xtr += w * r * x;
      sts += w * sgn * sgn;
      str += w * sgn * r;
    }
    // Fewer than two distinct positions along the line: nothing to eliminate against (the
    // determinant is a weighted variance of t times the weight sum; 1e-9 of its scale is
    // rounding).
    const double det = xtx(0, 0) * xtx(1, 1) - xtx(0, 1) * xtx(1, 0);
    if (!(det > 1e-9 * xtx(0, 0) * xtx(1, 1))) continue;
    const Eigen::Vector2d ks = Eigen::Vector2d(xtx(1, 1) * xts(0) - xtx(0, 1) * xts(1),
                                               xtx(0, 0) * xts(1) - xtx(1, 0) * xts(0)) /
                               det;
    num += str - xtr.dot(ks);
    den += sts - xts.dot(ks);
    total += sts;
  }
  // A line of one polarity leaves nothing once its offset is eliminated (its share of den is
  // 0 up to rounding); 1e-6 of the weights is far below any real second polarity.
  return den > 1e-6 * total ? num / den : 0.0;
}

struct Refined {
  std::vector<Eigen::Vector2d> uv_px;  // by feature id
  Eigen::Matrix3d H = Eigen::Matrix3d::Identity();
};

// Refines every feature from the coarse H_image_board (three passes, see the header) and
// checks the whole board. *reason on failure.
std::optional<Refined> RefineBoard(const ImageView8& image, const Board& board,
                                   const ChessModel& model, const Eigen::Matrix3d& H_coarse,
                                   const ChessboardOptions& options, DetectReason* reason) {
  *reason = DetectReason::kVerificationFailed;
  const std::vector<BoardFeature>& features = board.features();
  std::vector<Eigen::Vector2d> p_board;
  for (const BoardFeature& f : features) p_board.push_back(f.p_board);
  Refined r;
  r.H = H_coarse;
  // Three: the coarse points (contour corners, edge ends) are off by up to two pixels, so
  // the first pass's windows may clip an edge; the second starts within a fraction of a
  // pixel, the third from there is converged and corrects the edge bias (EdgeBiasPx).
  constexpr int kPasses = 3;
  for (int pass = 0; pass < kPasses; ++pass) {
    const std::optional<std::vector<MeasuredLine>> measured = MeasureEdges(image, model, r.H);
    if (!measured) return std::nullopt;
    std::vector<Line2d> lines;
    for (const MeasuredLine& m : *measured) {
      const std::optional<Line2d> line = FitEdgeLine(m, 0.0, std::nullopt);
      if (!line) return std::nullopt;
      lines.push_back(*line);
    }
    r.uv_px.assign(features.size(), Eigen::Vector2d::Zero());
    // The X-corners first (the last pass refines them by the saddle fit, started at their
    // line intersection, which the edge bias turns the lines about but does not move).
    for (std::size_t id = 0; id < features.size(); ++id) {
      const FeatureModel& fm = model.features[id];
      if (!fm.x_corner) continue;
      std::optional<Eigen::Vector2d> uv = IntersectLines(lines[fm.h_line], lines[fm.v_line]);
      if (!uv) return std::nullopt;
      if (pass == kPasses - 1) {
        const double side_px = LocalSquareSide(r.H, p_board[id], model.square_m);
        uv = RefineXCornerOnPatch(image, *uv, side_px, kSaddleBlurSigmaPx);
        if (!uv) return std::nullopt;
      }
      r.uv_px[id] = *uv;
    }
    if (pass == kPasses - 1) {
      // The lines refitted with their group's edge bias undone (EdgeBiasPx). A line of one
      // side (8 px of a foreshortened 12 px square, a third of it measured) has a direction
      // good to a few degrees under noise; the homography of the previous pass's 20
      // corners gives it far better, so such a line keeps only its measured offset.
      const std::array<double, 2> bias = {EdgeBiasPx(model, 0, *measured, lines),
                                          EdgeBiasPx(model, 1, *measured, lines)};
      for (std::size_t l = 0; l < lines.size(); ++l) {
        const EdgeLine& edge = model.lines[l];
        std::optional<Eigen::Vector2d> direction;
        if (edge.segments.size() == 1) {
          direction = (ApplyHomography(r.H, edge.segments[0].b_board) -
                       ApplyHomography(r.H, edge.segments[0].a_board))
                          .normalized();
        }
        const std::optional<Line2d> line = FitEdgeLine((*measured)[l], bias[edge.group], direction);
        if (!line) return std::nullopt;
        lines[l] = *line;
      }
    }
    for (std::size_t id = 0; id < features.size(); ++id) {
      const FeatureModel& fm = model.features[id];
      if (fm.x_corner) continue;
      const std::optional<Eigen::Vector2d> uv = IntersectLines(lines[fm.h_line], lines[fm.v_line]);
      if (!uv) return std::nullopt;
      r.uv_px[id] = *uv;
    }
    const std::optional<HomographyFit> fit = FitHomography(p_board, r.uv_px);
    if (!fit) return std::nullopt;
    r.H = fit->H;
  }
  for (std::size_t id = 0; id < features.size(); ++id) {
    const double side_px = LocalSquareSide(r.H, p_board[id], model.square_m);
    const double tol = std::max(0.5, options.max_residual_square_fraction * side_px);
    if (!((ApplyHomography(r.H, p_board[id]) - r.uv_px[id]).norm() <= tol)) return std::nullopt;
  }
  const double px_per_m =
      LocalSquareSide(r.H, Eigen::Vector2d::Zero(), model.square_m) / model.square_m;
  if (!PaintAgrees(board, r.H, image, px_per_m, options.min_paint_agreement)) {
    *reason = DetectReason::kWrongBoard;
    return std::nullopt;
  }
  *reason = DetectReason::kNone;
  return r;
}

Detection Fail(DetectReason reason) {
  Detection d;
  d.found = false;
  d.reason = reason;
  return d;
}

// ---- Splitting squares merged at X-corners ----------------------------------------------

// Components up to this fraction of the image's larger side are searched for X-corners: a
// group spans 550 / 2600 of the board's width, and the board at most the image's width
// (docs/acceptance.md: 80 %), so a third holds a group with clutter attached and skips walls.
constexpr double kMaxSplitComponentFraction = 1.0 / 3.0;
// Dark pixels closer than this to either edge line of a split X-corner turn light: two
// pixels in opposite dark sectors that are 4-neighbours would have to change their distance
// to both lines by more than a pixel in one step, which a unit step cannot.
constexpr double kSplitBandHalfWidthPx = 0.5;

// Splits dark components that are not quads at the X-corners inside them: squares of a
// group touching at an X-corner merge into one 4-connected component where blur and noise
// bridge the vertex. Each component of plausible size that gave no quad is blurred on a
// patch around its bounding box and searched for X-corners (x_corners.h); around each, a
// disc of `dark` (half the side of the component's mean square) is repainted from the
// corner's model: dark in the two dark sectors, light in the bright ones and on a band
// along both edge lines. Returns the number of
// X-corners split. Cost: the blur and the corner response over the patches only.
int SplitAtXCorners(const ImageView8& image, const ComponentLabels& labels,
                    const std::vector<bool>& has_quad, int min_side_px, Image8* dark) {
  const XCornerOptions corner_options;
  // The patch holds the ring, one more pixel for the response's non-maximum window and the
  // blur kernel (3 sigma) clear of the patch border, where the blur is clamped.
  const int pad = static_cast<int>(std::ceil(corner_options.ring_radius_px)) + 1 +
                  static_cast<int>(std::ceil(3.0 * kSaddleBlurSigmaPx));
  const int max_side =
      static_cast<int>(kMaxSplitComponentFraction * std::max(image.width, image.height));
  int splits = 0;
  for (std::size_t c = 0; c < labels.components.size(); ++c) {
    if (has_quad[c]) continue;
    const Component& comp = labels.components[c];
    const int w = comp.max_x - comp.min_x + 1;
    const int h = comp.max_y - comp.min_y + 1;
    if (std::max(w, h) < min_side_px || std::max(w, h) > max_side) continue;
    const int x0 = std::max(0, comp.min_x - pad);
    const int y0 = std::max(0, comp.min_y - pad);
    const int x1 = std::min(image.width, comp.max_x + 1 + pad);
    const int y1 = std::min(image.height, comp.max_y + 1 + pad);
    ImageView8 patch;
    patch.data = image.Row(y0) + x0;
    patch.width = x1 - x0;
    patch.height = y1 - y0;
    patch.stride_bytes = image.stride_bytes;
    const ImageF blurred = GaussianBlur(patch, kSaddleBlurSigmaPx);
    std::vector<XCorner> inside;
    for (XCorner& corner : FindXCorners(blurred, corner_options)) {
      corner.uv_px += Eigen::Vector2d(x0, y0);
      const Eigen::Vector2d& v = corner.uv_px;
      // Corners in the padding belong to other components.
      if (v.x() >= comp.min_x && v.x() <= comp.max_x && v.y() >= comp.min_y &&
          v.y() <= comp.max_y) {
        inside.push_back(corner);
      }
    }
    if (inside.empty()) continue;
    // The component holds one square more than X-corners; half the side of their mean
    // area stays inside the squares at each vertex (the shortest side under 50 degrees of
    // perspective is about two thirds of the mean), and reaches along a thin bright sector
    // as far as the bridge that blur and noise left.
    const double side_px = std::sqrt(comp.area_px / (inside.size() + 1.0));
    const double radius = std::max(corner_options.ring_radius_px, 0.5 * side_px);
    const int reach = static_cast<int>(std::ceil(radius));
    for (const XCorner& corner : inside) {
      const Eigen::Vector2d& v = corner.uv_px;
      const Eigen::Vector2d n_a(-corner.line_a.y(), corner.line_a.x());
      const Eigen::Vector2d n_b(-corner.line_b.y(), corner.line_b.x());
      // Sectors are the sign pairs of the distances to the two lines; opposite sectors have
      // the same product of signs, so the dark ones are those of the dark axis's product.
      const bool dark_product_positive =
          (n_a.dot(corner.dark_axis) > 0.0) == (n_b.dot(corner.dark_axis) > 0.0);
      const int cx = static_cast<int>(std::lround(v.x()));
      const int cy = static_cast<int>(std::lround(v.y()));
      for (int y = std::max(0, cy - reach); y <= std::min(image.height - 1, cy + reach); ++y) {
        for (int x = std::max(0, cx - reach); x <= std::min(image.width - 1, cx + reach); ++x) {
          const Eigen::Vector2d d = Eigen::Vector2d(x, y) - v;
          if (d.squaredNorm() > radius * radius) continue;
          const double da = n_a.dot(d);
          const double db = n_b.dot(d);
          const bool in_dark_sector = ((da > 0.0) == (db > 0.0)) == dark_product_positive;
          const bool clear_of_lines =
              std::abs(da) > kSplitBandHalfWidthPx && std::abs(db) > kSplitBandHalfWidthPx;
          dark->at(x, y) = in_dark_sector && clear_of_lines ? 1 : 0;
        }
      }
      ++splits;
    }
  }
  return splits;
}

// ---- The search over one binarisation --------------------------------------------------

// The quads of `dark`'s components (*labels: their labelling, kept for splitting).
std::vector<SquareQuad> SquareQuads(const Image8& dark, const ChessboardOptions& options,
                                    ComponentLabels* labels) {
  *labels = LabelComponents(dark.view());
  QuadOptions quad_options;
  quad_options.min_side_px = options.min_square_side_px;
  std::vector<SquareQuad> quads;
  for (const Quad& q : FindQuads(*labels, quad_options)) {
    SquareQuad s;
    s.corners_px = q.corners_px;
    s.component = q.component;
    for (int k = 0; k < 4; ++k) {
      s.centre_px += 0.25 * q.corners_px[k];
      s.side_px += 0.25 * (q.corners_px[(k + 1) % 4] - q.corners_px[k]).norm();
    }
    quads.push_back(s);
  }
  return quads;
}

// The board from image points of known board positions, each with its coarse tolerance,
// pixels: the coarse homography must fit every point within its tolerance; then the upright
// orientation (header), refinement and the whole-board checks (RefineBoard). nullopt when
// any step fails; *failure is raised to the furthest stage reached.
std::optional<Refined> FitAndRefineBoard(const ImageView8& image, const Board& board,
                                         const ChessModel& model,
                                         std::span<const Eigen::Vector2d> board_pts,
                                         std::span<const Eigen::Vector2d> image_pts,
                                         std::span<const double> tolerance,
                                         const ChessboardOptions& options, DetectReason* failure) {
  *failure = std::max(*failure, DetectReason::kVerificationFailed);
  HomographyFitOptions dlt;
  dlt.refine = false;  // coarse: the points are off by a pixel anyway
  const std::optional<HomographyFit> fit = FitHomography(board_pts, image_pts, dlt);
  if (!fit) return std::nullopt;
  std::vector<double> residuals;
  HomographyResiduals(fit->H, board_pts, image_pts, &residuals);
  for (std::size_t i = 0; i < residuals.size(); ++i) {
    if (!(residuals[i] <= tolerance[i])) return std::nullopt;
  }
  // The upright one of the two orientations (header): board +x along image +u.
  Eigen::Matrix3d H = fit->H;
  const Eigen::Vector2d centre = ApplyHomography(H, Eigen::Vector2d::Zero());
  const Eigen::Vector2d x_axis = ApplyHomography(H, Eigen::Vector2d(model.square_m, 0.0)) - centre;
  if (x_axis.x() < 0.0) H = H * Eigen::Vector3d(-1.0, -1.0, 1.0).asDiagonal();
  DetectReason reason = DetectReason::kNone;
  std::optional<Refined> refined = RefineBoard(image, board, model, H, options, &reason);
  if (!refined) *failure = std::max(*failure, reason);
  return refined;
}

// Every pair of groups with distinct quads (found on pyramid level `level`, in its pixels):
// the coarse board homography from their 24 corners in full-resolution pixels, then
// refinement and the whole-board checks on the full-resolution `image`. The verified
// boards; *failure is raised to the furthest stage reached (DetectReason's order).
std::vector<Refined> SearchBoards(const ImageView8& image, int level, const Board& board,
                                  const ChessModel& model, const std::vector<SquareQuad>& quads,
                                  const ChessboardOptions& options, DetectReason* failure) {
  std::vector<Refined> found;
  if (quads.empty()) return found;
  const std::vector<Triple> triples = FindTriples(quads, options);
  if (triples.size() < 2) {
    *failure = std::max(*failure, DetectReason::kTooFewFeatures);
    return found;
  }
  std::vector<Eigen::Vector2d> local, image_pts, board_pts;
  std::vector<double> tolerance;
  for (std::size_t a = 0; a < triples.size(); ++a) {
    for (std::size_t b = a + 1; b < triples.size(); ++b) {
      const Triple& ta = triples[a];
      const Triple& tb = triples[b];
      if (std::any_of(ta.quads.begin(), ta.quads.end(), [&](int q) {
            return std::find(tb.quads.begin(), tb.quads.end(), q) != tb.quads.end();
          })) {
        continue;
      }
      board_pts.clear();
      image_pts.clear();
      tolerance.clear();
      for (int g = 0; g < 2; ++g) {
        const Triple& t = g == 0 ? ta : tb;
        local.clear();
        TriplePoints(t, quads, &local, &image_pts);
        for (const Eigen::Vector2d& l : local) board_pts.push_back(model.groups[g].ToBoard(l));
        tolerance.resize(image_pts.size(), (1 << level) * CoarseTolerancePx(options, t.side_px));
      }
      for (Eigen::Vector2d& p : image_pts) p = LevelToImage(p, level);
      std::optional<Refined> refined =
          FitAndRefineBoard(image, board, model, board_pts, image_pts, tolerance, options, failure);
      if (refined) found.push_back(*std::move(refined));
    }
  }
  return found;
}

// ---- Second path: groups seeded from their pairs of X-corners ----------------------------

// A group's two X-corners lie one square side apart on one edge line, with the middle
// square between them on one side of that line (GroupModel: local (0, 0) and (1, 0)).
// Each of the pair's corners has one edge line within this angle of the line joining them
// (LinkXCorners' 25 degrees: the ring's directions are good to a few degrees, perspective
// does not bend lines).
const double kPairLineCos = std::cos(25.0 * std::numbers::pi / 180.0);
// Their dark axes bisect the same two lines' sectors turned by a quarter turn: |cos| below
// 0.5 (60 degrees) allows for strong perspective (as LinkXCorners).
constexpr double kPairMaxDarkAxisCos = 0.5;
// The pair is at least this far apart (LinkXCorners' minimum): 12 px squares at 50 degrees
// of both yaw and pitch and rolled are about 5 px along one side.
constexpr double kMinPairPx = 4.0;

// Edge-end scan (EdgeEndPx): samples every half pixel (the end is interpolated between
// them); the grey-level difference across the edge is taken at this fraction of the square
// side on either side of it (beyond the blur of the edge, 2 px at most in docs/acceptance.md,
// well inside the square), at least 1 px (where an edge blurred by 2 px still shows 40 % of
// its contrast, and the scan can start within 3 px of the vertex: 5 px squares).
constexpr double kEndScanStepPx = 0.5;
constexpr double kEndOffsetSideFraction = 0.2;
constexpr double kMinEndOffsetPx = 1.0;
// The edge's difference near its start must reach this fraction of the X-corner's ring
// contrast (the same print's edge; the ring sees it at 4 px, an edge sample at 1.5 px sees
// about half of it): contrast-adaptive, so a dim or low-gamma print works.
constexpr double kMinEndContrastFraction = 0.3;
// At most this many pairs of groups are fitted and refined as a board on one level (the
// groups of the strongest X-corners first): a board's two groups are among them, while a
// texture of X-corners (a fuzzed image: 25 s under the sanitizers) makes hundreds of groups
// whose pairs on one line are then tried one by one.
constexpr int kMaxPairBoardFits = 64;
// A square's side along one edge line is at most this many times its side along the
// other: 50 degrees of foreshortening (1 / cos 50 = 1.6) with the rest of the
// perspective of docs/acceptance.md's views; plus 2 px for the smallest squares.
constexpr double kMaxSideRatio = 3.0;
constexpr double kMaxEndExtraPx = 2.0;

// Where the straight edge leaving start_px along the unit `dir` ends at a black square's
// corner against white: the distance, pixels, at which the grey-level difference across the
// edge (blurred image, samples at +-offset_px along the normal) has fallen to half its
// largest value so far — at a blurred right-angled corner the sample on the dark side sees
// half of the square there (short, blurred edges end up to a pixel or two early). Scanned from 1.5
// offset_px + 1 px (clear of the other sectors at an X-corner, whose sectors span at least 35
// degrees: cot 35 = 1.43) to max_px. nullopt when the edge is weaker than min_contrast, when the
// scan leaves the image or when the edge does not end. Cost: O(max_px) bilinear samples.
std::optional<double> EdgeEndPx(const ImageF& blurred, const Eigen::Vector2d& start_px,
                                const Eigen::Vector2d& dir, double offset_px, double max_px,
                                double min_contrast) {
  const Eigen::Vector2d n(-dir.y(), dir.x());
  const auto difference = [&](double t) -> std::optional<double> {
    const Eigen::Vector2d p = start_px + t * dir;
    const Eigen::Vector2d a = p + offset_px * n;
    const Eigen::Vector2d b = p - offset_px * n;
    for (const Eigen::Vector2d& q : {a, b}) {
      if (!(q.x() >= 0.0 && q.y() >= 0.0 && q.x() <= blurred.width - 1.0 &&
            q.y() <= blurred.height - 1.0)) {
        return std::nullopt;
      }
    }
    return SampleBilinear(blurred, a.x(), a.y()) - SampleBilinear(blurred, b.x(), b.y());
  };
  const double t0 = 1.5 * offset_px + 1.0;
  const std::optional<double> first = difference(t0);
  if (!first) return std::nullopt;
  // The edge's side: the sign of the difference at the start; its contrast: the largest
  // difference seen so far (perspective and blur make short edges a ramp, not a plateau).
  const double sign = *first > 0.0 ? 1.0 : -1.0;
  double peak = 0.0;
  double previous = 0.0;
  for (double t = t0; t <= max_px; t += kEndScanStepPx) {
    const std::optional<double> c = difference(t);
    if (!c) return std::nullopt;
    const double value = sign * *c;
    if (value < 0.5 * peak) {
      if (peak < min_contrast) return std::nullopt;
      return t - kEndScanStepPx * (0.5 * peak - value) / (previous - value);
    }
    peak = std::max(peak, value);
    previous = value;
  }
  return std::nullopt;
}

// A group seen from its pair of X-corners: image points at local grid positions
// (GroupModel) and the side of its middle square, pixels.
struct PairGroup {
  std::array<int, 2> corners = {0, 0};  // the X-corners at local (0, 0) and (1, 0)
  std::vector<Eigen::Vector2d> local;
  std::vector<Eigen::Vector2d> image_px;
  double side_px = 0.0;
};

// The group seeded by X-corners p (local (0, 0)) and q (local (1, 0)), the middle square on
// the image side of +90 degrees from p -> q (GroupModel's handedness): the six edge ends
// on the pair's three edge lines (local (0, +-1), (1, +-1), (-1, 0), (2, 0)) found by
// EdgeEndPx, then a homography of the eight points within the coarse tolerance.
std::optional<PairGroup> GroupFromPair(const ImageF& blurred, const std::vector<XCorner>& corners,
                                       int p, int q, const ChessboardOptions& options) {
  const XCorner& cp = corners[p];
  const XCorner& cq = corners[q];
  const Eigen::Vector2d pq = cq.uv_px - cp.uv_px;
  const double side_px = pq.norm();
  const Eigen::Vector2d e = pq / side_px;
  const Eigen::Vector2d gy(-e.y(), e.x());
  // The other edge line at each corner (the one less aligned with p -> q), towards +gy.
  const auto other_line = [&](const XCorner& c) {
    Eigen::Vector2d l = std::abs(c.line_a.dot(e)) < std::abs(c.line_b.dot(e)) ? c.line_a : c.line_b;
    return l.dot(gy) < 0.0 ? Eigen::Vector2d(-l) : l;
  };
  const Eigen::Vector2d lp = other_line(cp);
  const Eigen::Vector2d lq = other_line(cq);
  const double offset = std::max(kMinEndOffsetPx, kEndOffsetSideFraction * side_px);
  const double max_px = kMaxSideRatio * side_px + kMaxEndExtraPx;
  struct Scan {
    const XCorner* from;
    Eigen::Vector2d dir;
    Eigen::Vector2d local;
  };
  const std::array<Scan, 6> scans = {{{&cp, lp, {0, 1}},
                                      {&cp, -lp, {0, -1}},
                                      {&cq, lq, {1, 1}},
                                      {&cq, -lq, {1, -1}},
                                      {&cp, -e, {-1, 0}},
                                      {&cq, e, {2, 0}}}};
  PairGroup g;
  g.corners = {p, q};
  g.local = {Eigen::Vector2d(0, 0), Eigen::Vector2d(1, 0)};
  g.image_px = {cp.uv_px, cq.uv_px};
  for (const Scan& s : scans) {
    const std::optional<double> t = EdgeEndPx(blurred, s.from->uv_px, s.dir, offset, max_px,
                                              kMinEndContrastFraction * s.from->contrast);
    if (!t) return std::nullopt;
    g.local.push_back(s.local);
    g.image_px.push_back(s.from->uv_px + *t * s.dir);
  }
  HomographyFitOptions dlt;
  dlt.refine = false;  // coarse: edge ends are off by about a pixel
  const std::optional<HomographyFit> fit = FitHomography(g.local, g.image_px, dlt);
  if (!fit) return std::nullopt;
  g.side_px = LocalSquareSide(fit->H, Eigen::Vector2d(0.0, 0.0), 1.0);
  if (!(fit->max_residual <= CoarseTolerancePx(options, g.side_px))) return std::nullopt;
  return g;
}

// The groups seeded from every pair of X-corners that could be a group's (see kPairLineCos
// and kPairMaxDarkAxisCos; the dark sector of each facing the other on the same side of
// their line: the middle square). Pairs longer than max_pair_px are skipped.
std::vector<PairGroup> PairGroups(const ImageF& blurred, const std::vector<XCorner>& corners,
                                  double max_pair_px, const ChessboardOptions& options) {
  std::vector<PairGroup> groups;
  const int n = static_cast<int>(corners.size());
  for (int i = 0; i < n; ++i) {
    for (int j = i + 1; j < n; ++j) {
      const XCorner& a = corners[i];
      const XCorner& b = corners[j];
      const Eigen::Vector2d d = b.uv_px - a.uv_px;
      const double dist = d.norm();
      if (dist < kMinPairPx || dist > max_pair_px) continue;
      const Eigen::Vector2d e = d / dist;
      const auto on_line = [&](const XCorner& c) {
        return std::max(std::abs(c.line_a.dot(e)), std::abs(c.line_b.dot(e))) >= kPairLineCos;
      };
      if (!on_line(a) || !on_line(b)) continue;
      if (std::abs(a.dark_axis.dot(b.dark_axis)) > kPairMaxDarkAxisCos) continue;
      // The side of the line a -> b holding each corner's dark sector that faces the other.
      const Eigen::Vector2d normal(-e.y(), e.x());
      const Eigen::Vector2d da = a.dark_axis.dot(e) > 0.0 ? a.dark_axis : -a.dark_axis;
      const Eigen::Vector2d db = b.dark_axis.dot(e) < 0.0 ? b.dark_axis : -b.dark_axis;
      const double side_a = normal.dot(da);
      const double side_b = normal.dot(db);
      if ((side_a > 0.0) != (side_b > 0.0)) continue;
      std::optional<PairGroup> g = side_a > 0.0 ? GroupFromPair(blurred, corners, i, j, options)
                                                : GroupFromPair(blurred, corners, j, i, options);
      if (g) groups.push_back(*std::move(g));
    }
  }
  return groups;
}

// Both groups' X-corners lie on one board line (MakeModel checks it), so b's are on the
// image line through a's: within half of the larger side plus a pixel of the level the
// corners were found on, `scale` image pixels (the line's direction from two saddle points
// a side apart, extrapolated over the 13 sides between the groups, is good to a quarter of
// a side). A cheap gate before the board homography: clutter and checkers give many pairs
// of groups, few of them on one line. O(1).
bool OnOneLine(const std::vector<XCorner>& corners, const PairGroup& a, const PairGroup& b,
               double scale) {
  const Eigen::Vector2d& p = corners[a.corners[0]].uv_px;
  const Eigen::Vector2d d = (corners[a.corners[1]].uv_px - p).normalized();
  const Eigen::Vector2d n(-d.y(), d.x());
  const double tol = 0.5 * std::max(a.side_px, b.side_px) + scale;
  return std::abs(n.dot(corners[b.corners[0]].uv_px - p)) <= tol &&
         std::abs(n.dot(corners[b.corners[1]].uv_px - p)) <= tol;
}

// The second path on one pyramid level (`view`: the image halved `level` times, level 0
// the image itself; header, step 6): X-corners over the level, groups from their pairs, and
// every two groups with distinct corners as the board's left and right group (either way
// round) through FitAndRefineBoard, which refines and verifies on the full-resolution
// `image` (its coarse tolerance scaled to it with the points).
std::vector<Refined> SearchPairBoards(const ImageView8& image, const ImageView8& view, int level,
                                      const Board& board, const ChessModel& model, int min_contrast,
                                      const ChessboardOptions& options, DetectReason* failure) {
  std::vector<Refined> found;
  XCornerOptions corner_options;
  // The ring's contrast floor rises with the image's noise like the binarisation's (halving
  // only lowers the noise).
  corner_options.min_contrast =
      std::max(corner_options.min_contrast, static_cast<double>(min_contrast));
  // A 3 px ring (default 4): 12 px squares at 50 degrees of yaw and pitch are 5-8 px along
  // a side, where a 4 px ring reaches the neighbouring L-corners and noise breaks its
  // sector test; 3 px stays outside the 1.5 px blur.
  constexpr double kPairRingRadiusPx = 3.0;
  corner_options.ring_radius_px = kPairRingRadiusPx;
  const ImageF blurred = GaussianBlur(view, kSaddleBlurSigmaPx);
  std::vector<XCorner> corners = FindXCorners(blurred, corner_options);
  // A group's pair is one square apart: a square is 150 / 2600 of a board at most the
  // image's width (docs/acceptance.md: 80 %); a tenth of the larger side allows perspective.
  constexpr double kMaxPairImageFraction = 0.1;
  const double max_pair_px = kMaxPairImageFraction * std::max(view.width, view.height);
  std::vector<PairGroup> groups = PairGroups(blurred, corners, max_pair_px, options);
  if (groups.size() < 2) {
    *failure = std::max(*failure, DetectReason::kTooFewFeatures);
    return found;
  }
  // From here on full-resolution pixels: the points, and the tolerances scaled with them.
  const double scale = static_cast<double>(1 << level);
  for (XCorner& c : corners) c.uv_px = LevelToImage(c.uv_px, level);
  for (PairGroup& g : groups) {
    for (Eigen::Vector2d& p : g.image_px) p = LevelToImage(p, level);
    g.side_px *= scale;
  }
  std::vector<Eigen::Vector2d> image_pts, board_pts;
  std::vector<double> tolerance;
  int fits = 0;
  for (std::size_t a = 0; a < groups.size() && fits < kMaxPairBoardFits; ++a) {
    for (std::size_t b = a + 1; b < groups.size() && fits < kMaxPairBoardFits; ++b) {
      const PairGroup& ga = groups[a];
      const PairGroup& gb = groups[b];
      if (std::any_of(ga.corners.begin(), ga.corners.end(), [&](int c) {
            return std::find(gb.corners.begin(), gb.corners.end(), c) != gb.corners.end();
          })) {
        continue;
      }
      if (!OnOneLine(corners, ga, gb, scale) || !OnOneLine(corners, gb, ga, scale)) continue;
      for (int left_first = 0; left_first < 2; ++left_first) {
        board_pts.clear();
        image_pts.clear();
        tolerance.clear();
        for (int g = 0; g < 2; ++g) {
          const PairGroup& pg = (g == 0) == (left_first == 1) ? ga : gb;
          for (std::size_t k = 0; k < pg.local.size(); ++k) {
            board_pts.push_back(model.groups[g].ToBoard(pg.local[k]));
            image_pts.push_back(pg.image_px[k]);
            tolerance.push_back(scale * CoarseTolerancePx(options, pg.side_px / scale));
          }
        }
        ++fits;
        std::optional<Refined> refined = FitAndRefineBoard(image, board, model, board_pts,
                                                           image_pts, tolerance, options, failure);
        if (refined) {
          found.push_back(*std::move(refined));
          break;
        }
      }
    }
  }
  return found;
}

// The verified boards are one board found more than once (from duplicate groups): every
// feature within a pixel of the first's; otherwise two boards are in view. O(boards).
bool OneBoard(const std::vector<Refined>& found) {
  for (const Refined& other : found) {
    for (std::size_t id = 0; id < other.uv_px.size(); ++id) {
      if ((other.uv_px[id] - found[0].uv_px[id]).norm() > 1.0) return false;
    }
  }
  return true;
}

// Steps 1-6 of the header on pyramid level `level` (`view`: the image halved `level`
// times, level 0 the image itself): the blob path, the split and the second path, with
// the candidates found on `view` and refined and verified on `image`. The verified boards;
// *failure is raised to the furthest stage reached, kLowContrast when the level has no
// contrast above min_contrast.
std::vector<Refined> SearchLevel(const ImageView8& image, const ImageView8& view, int level,
                                 const Board& board, const ChessModel& model, int min_contrast,
                                 const ChessboardOptions& options, DetectReason* failure) {
  int max_contrast = 0;
  Image8 dark = BinariseDark(view, min_contrast, &max_contrast);
  if (max_contrast < min_contrast) {
    *failure = DetectReason::kLowContrast;
    return {};
  }
  ComponentLabels labels;
  std::vector<SquareQuad> quads = SquareQuads(dark, options, &labels);
  std::vector<Refined> found = SearchBoards(image, level, board, model, quads, options, failure);
  if (found.empty()) {
    // Second chance: squares merged at X-corners, split and searched again.
    std::vector<bool> has_quad(labels.components.size(), false);
    for (const SquareQuad& q : quads) has_quad[q.component] = true;
    if (SplitAtXCorners(view, labels, has_quad, options.min_square_side_px, &dark) > 0) {
      quads = SquareQuads(dark, options, &labels);
      found = SearchBoards(image, level, board, model, quads, options, failure);
    }
  }
  if (found.empty()) {
    found = SearchPairBoards(image, view, level, board, model, min_contrast, options, failure);
  }
  return found;
}

}  // namespace

std::string_view ChessboardOptions::Validate() const {
  if (min_contrast < 1 || min_contrast > 255) return "min_contrast";
  if (!(noise_contrast_factor >= 0.0 && noise_contrast_factor <= 100.0)) {
    return "noise_contrast_factor";
  }
  if (min_square_side_px < 4 || min_square_side_px > 64) return "min_square_side_px";
  if (!(touch_fraction > 0.0 && touch_fraction <= 0.5)) return "touch_fraction";
  if (!(coarse_residual_fraction > 0.0 && coarse_residual_fraction <= 0.5)) {
    return "coarse_residual_fraction";
  }
  if (!(max_residual_square_fraction > 0.0 && max_residual_square_fraction <= 0.5)) {
    return "max_residual_square_fraction";
  }
  if (!(min_paint_agreement >= 0.0 && min_paint_agreement <= 1.0)) return "min_paint_agreement";
  return {};
}

Detection DetectChessboard(const ImageView8& image, const Board& board,
                           const ChessboardOptions& options) {
  if (const DetectReason r =
          CheckDetectorInput(image, board, BoardType::kChessboard, options.Validate().empty());
      r != DetectReason::kNone) {
    return Fail(r);
  }
  const std::optional<ChessModel> model = MakeModel(board);
  if (!model) return Fail(DetectReason::kWrongBoard);

  const double noise_sigma = EstimateNoiseSigma(image);
  const int min_contrast =
      std::max(options.min_contrast,
               static_cast<int>(std::ceil(options.noise_contrast_factor * noise_sigma)));
  // Coarse to fine (x_corners.h, kMinCoarseLevelSidePx): the whole search on each halving of
  // the image from the coarsest, then on the image itself, until a level finds one board
  // (duplicates of it allowed). Refinement and the whole-board checks are at full
  // resolution whatever the level, so a board found coarse is as accurate as one found on
  // the image. Anything else on a coarse level (nothing, or two boards that disagree)
  // passes on to the finer levels, so the image itself decides, with the reason reported
  // without the coarse levels; boards too small for the coarse levels, and images without
  // a board, pay for the coarse levels on top (at most a third more).
  const std::vector<Image8> pyramid = HalvingPyramid(image, kMinCoarseLevelSidePx);
  std::vector<Refined> found;
  DetectReason failure = DetectReason::kNoCandidates;
  for (int level = static_cast<int>(pyramid.size()); level >= 0; --level) {
    failure = DetectReason::kNoCandidates;
    found = SearchLevel(image, level == 0 ? image : pyramid[level - 1].view(), level, board, *model,
                        min_contrast, options, &failure);
    if (!found.empty() && OneBoard(found)) break;
  }
  if (found.empty()) return Fail(failure);
  if (!OneBoard(found)) return Fail(DetectReason::kAmbiguous);
  Detection d;
  d.found = true;
  d.reason = DetectReason::kNone;
  for (std::size_t id = 0; id < found[0].uv_px.size(); ++id) {
    const BoardFeature& f = board.features()[id];
    d.features.push_back({f.id, found[0].uv_px[id], f.p_board, f.marker});
  }
  return d;
}

}  // namespace linecal
