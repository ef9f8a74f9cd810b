#include "detectors/square_grid/square_grid_detector.h"

#include <Eigen/LU>
#include <algorithm>
#include <array>
#include <cmath>
#include <deque>
#include <limits>
#include <map>
#include <optional>
#include <set>
#include <utility>
#include <vector>

#include "detectors/common/binarise.h"
#include "detectors/common/contours.h"
#include "detectors/common/edge_lines.h"
#include "detectors/common/homography.h"

namespace linecal {
namespace {

// ---- 1. Dark squares ------------------------------------------------------------------------

// Edge points per side for the line fits, spread over the side's middle 70% (the corners
// are rounded by blur and touch the gaps' crossings): enough for a fit that averages noise,
// few enough for squares of min_square_side_px.
constexpr int kEdgeSamples = 12;
constexpr double kEdgeSpan = 0.7;

// A dark quad: corners clockwise in the image (y down), its homography from the unit square
// ((0, 0) corner 0, (1, 0) corner 1, (1, 1) corner 2, (0, 1) corner 3), centre and mean side.
struct Square {
  std::array<Eigen::Vector2d, 4> corners;
  Eigen::Matrix3d H = Eigen::Matrix3d::Identity();
  Eigen::Vector2d centre = Eigen::Vector2d::Zero();
  double side_px = 0.0;
  double edge_rms_px = 0.0;  // its edge points' RMS distance from their side's line, worst side
};

// The quad's corners where lines fitted to its four edges meet (edge points from dark inside
// to light outside, edge_lines.h); the window across an edge stays clear of the opposite side
// and of the next square beyond the gap (gap_ratio sides away). nullopt when a side has too
// few edge points, two sides are near parallel, or a corner moves by more than a third of a
// side (not a square's corner: the contour's vertices of a blurred, noisy square of 12-16 px
// lie up to a quarter of a side off its corners). *edge_rms_px: the edge points' RMS distance
// from their side's line, the largest over the four sides (how straight the sides are).
std::optional<std::array<Eigen::Vector2d, 4>> RefineCorners(
    const ImageView8& image, const std::array<Eigen::Vector2d, 4>& corners, double gap_ratio,
    double* edge_rms_px) {
  std::array<Line2d, 4> lines;
  *edge_rms_px = 0.0;
  for (int k = 0; k < 4; ++k) {
    const Eigen::Vector2d a = corners[k], b = corners[(k + 1) % 4];
    const double len = (b - a).norm();
    const Eigen::Vector2d d = (b - a) / len;
    const Eigen::Vector2d n(d.y(), -d.x());  // outward for a clockwise quad, y down
    // 4 px: beyond it only the tail of the blur is seen.
    const double half_window = std::clamp(0.4 * std::min(1.0, gap_ratio) * len, 1.0, 4.0);
    std::vector<EdgePoint> points;
    for (int i = 0; i < kEdgeSamples; ++i) {
      const double t = 0.5 * (1.0 - kEdgeSpan) + kEdgeSpan * (i + 0.5) / kEdgeSamples;
      if (const std::optional<EdgePoint> e =
              MeasureEdgePoint(image, a + t * (b - a), n, half_window)) {
        points.push_back(*e);
      }
    }
    // Half the samples: a side mostly without an edge is not a printed square's.
    if (static_cast<int>(points.size()) < kEdgeSamples / 2) return std::nullopt;
    const std::optional<Line2d> line = FitWeightedLine(points, d);
    if (!line) return std::nullopt;
    lines[k] = *line;
    const Eigen::Vector2d normal(line->dir.y(), -line->dir.x());
    double sum_sq = 0.0;
    for (const EdgePoint& e : points) sum_sq += std::pow((e.uv_px - line->point).dot(normal), 2);
    *edge_rms_px = std::max(*edge_rms_px, std::sqrt(sum_sq / static_cast<double>(points.size())));
  }
  std::array<Eigen::Vector2d, 4> out;
  for (int k = 0; k < 4; ++k) {
    const std::optional<Eigen::Vector2d> p = IntersectLines(lines[(k + 3) % 4], lines[k]);
    if (!p) return std::nullopt;
    out[k] = *p;
  }
  // Corner k ends side k - 1 and starts side k. The sides of the quad or of the refined
  // square, whichever is longer: a foreshortened square's contour at a dark surround (a
  // lens's rim) falls short of its corners by a good part of its short side.
  const auto shorter_side = [](const std::array<Eigen::Vector2d, 4>& q, int k) {
    return std::min((q[(k + 1) % 4] - q[k]).norm(), (q[k] - q[(k + 3) % 4]).norm());
  };
  for (int k = 0; k < 4; ++k) {
    const double side = std::max(shorter_side(corners, k), shorter_side(out, k));
    if ((out[k] - corners[k]).norm() > side / 3.0) return std::nullopt;
  }
  return out;
}

// The homography that maps the unit square's corners (0, 0), (1, 0), (1, 1), (0, 1) onto
// p[0] .. p[3], in closed form (the projective map of a square onto a quad: four points
// determine it exactly, so a least-squares fit is not needed, and costs some twenty times
// as much). nullopt when p[1], p[2] and p[3] are collinear or the map is singular.
std::optional<Eigen::Matrix3d> UnitSquareHomography(const std::array<Eigen::Vector2d, 4>& p) {
  const Eigen::Vector2d sum = p[0] - p[1] + p[2] - p[3];  // zero for a parallelogram
  const Eigen::Vector2d d1 = p[1] - p[2], d3 = p[3] - p[2];
  const double den = d1.x() * d3.y() - d3.x() * d1.y();
  if (!(std::abs(den) > 0.0)) return std::nullopt;
  // The bottom row: where the unit square's sides meet (0 for a parallelogram's image).
  const double g = (sum.x() * d3.y() - d3.x() * sum.y()) / den;
  const double h = (d1.x() * sum.y() - sum.x() * d1.y()) / den;
  Eigen::Matrix3d H;
  H << p[1].x() - p[0].x() + g * p[1].x(), p[3].x() - p[0].x() + h * p[3].x(), p[0].x(),
      p[1].y() - p[0].y() + g * p[1].y(), p[3].y() - p[0].y() + h * p[3].y(), p[0].y(),  //
      g, h, 1.0;
  if (!H.allFinite() || !(std::abs(H.determinant()) > 0.0)) return std::nullopt;
  return H;
}

// The square of four refined corners; nullopt when they give no homography.
std::optional<Square> MakeSquare(const std::array<Eigen::Vector2d, 4>& corners) {
  const std::optional<Eigen::Matrix3d> H = UnitSquareHomography(corners);
  if (!H) return std::nullopt;
  Square s;
  s.corners = corners;
  s.H = *H;
  s.centre = ApplyHomography(s.H, Eigen::Vector2d(0.5, 0.5));
  for (int k = 0; k < 4; ++k) s.side_px += 0.25 * (corners[(k + 1) % 4] - corners[k]).norm();
  if (!s.centre.allFinite()) return std::nullopt;
  return s;
}

// The quads of dark squares of at least min_side_px.
QuadOptions SquareQuadOptions(int min_side_px) {
  QuadOptions quad_options;
  quad_options.min_side_px = min_side_px;
  // A quarter of a side: the chamfer blur and noise leave at a small square's acute corner
  // (4 px of a 22 px side, seen on renders at yaw 30, pitch 30), never two of its corners.
  quad_options.merge_vertices_fraction = 0.06;
  // A blurred square under a gamma is rounded at every corner: up to two vertices each.
  quad_options.max_polygon_vertices = 8;
  return quad_options;
}

// The dark squares of the image: quads of the dark components, refined twice (the second fit
// starts from edges measured along the right normals).
std::vector<Square> FindSquares(const ImageView8& image, const Image8& dark, double gap_ratio,
                                int min_side_px) {
  std::vector<Square> squares;
  // Without the label image: only the quads' contours need the components' pixels.
  const ComponentLabels labels = LabelComponents(dark.view(), /*label_image=*/false);
  for (const Quad& quad : FindQuads(labels, SquareQuadOptions(min_side_px))) {
    std::optional<std::array<Eigen::Vector2d, 4>> corners = quad.corners_px;
    double edge_rms_px = 0.0;
    for (int pass = 0; pass < 2 && corners; ++pass) {
      corners = RefineCorners(image, *corners, gap_ratio, &edge_rms_px);
    }
    if (!corners) continue;
    if (std::optional<Square> s = MakeSquare(*corners)) {
      s->edge_rms_px = edge_rms_px;
      squares.push_back(*s);
    }
  }
  return squares;
}

// ---- 2. Links and grid coordinates --------------------------------------------------------

// Side k's outward direction in the unit square: up, right, down, left (clockwise, y down).
constexpr std::array<std::array<double, 2>, 4> kSideDirection = {
    {{0.0, -1.0}, {1.0, 0.0}, {0.0, 1.0}, {-1.0, 0.0}}};

// Two squares of one grid differ in size by perspective only: under 2:1 for any view the
// link test accepts, while dark shapes of the room come in every size.
constexpr double kMaxSideRatio = 2.0;

// A square beyond a window continues the grid only with sides as straight as the window's:
// its edge points' RMS distance from their sides' lines (Square::edge_rms_px) at most this
// times the window's least straight square's. A printed square is as straight as its
// neighbours (a factor of 2 leaves room for one further into a lens's bend); a dark disc
// just off the page, its tangent quad of 34 px, is at 1.32 px RMS and once passed the gap
// geometry (docs/detectors.md, "The two misses of the run of every board"), while the least
// straight square of every found window of detectors_eval is within 0.30 px.
constexpr double kMaxEdgeRmsRatio = 2.0;

struct Link {
  int square = -1;  // the neighbour, -1 for none
  int side = 0;     // its side that faces back
};

// Per square and side, the mutual neighbour across that side (method, step 2): the side of
// another square whose gap centre, each square's homography carried half a gap beyond its
// side, is nearest, within max_fraction of the two squares' mean side, both ways. Half a gap
// from each side keeps the bending of a lens out: a fisheye near the rim shrinks the pitch
// by a third from one square to the next, which a whole pitch carried by one square's
// homography misses by more than a quarter of it. The two half gaps, each seen through its
// own square's homography, must also agree within kMaxSideRatio (the gap is one for both): a
// dark clutter shape whose quad is far from any square's image carries its homography
// wildly, and its gap centre, 42 px from its side where half a gap of its 20 px is 10 px,
// once landed on a grid square's and took that square's grid point (docs/detectors.md, "The
// two misses of the run of every board").
std::vector<std::array<Link, 4>> LinkSquares(const std::vector<Square>& squares, double gap_ratio,
                                             double max_fraction) {
  const int n = static_cast<int>(squares.size());
  std::vector<std::array<Eigen::Vector2d, 4>> gap_centre(n);
  std::vector<std::array<double, 4>> half_gap(n);  // from the side's middle to gap_centre, px
  for (int a = 0; a < n; ++a) {
    for (int k = 0; k < 4; ++k) {
      const double reach = 0.5 + 0.5 * gap_ratio;  // from the square's centre, in sides
      const Eigen::Vector2d dir(kSideDirection[k][0], kSideDirection[k][1]);
      gap_centre[a][k] = ApplyHomography(squares[a].H, Eigen::Vector2d(0.5, 0.5) + reach * dir);
      half_gap[a][k] =
          (gap_centre[a][k] - ApplyHomography(squares[a].H, Eigen::Vector2d(0.5, 0.5) + 0.5 * dir))
              .norm();
    }
  }
  // Per square, the farthest of its gap centres from its centre (infinite when one is not
  // finite): two squares whose centres lie further apart than their two reaches and the
  // tolerance have no gap centres within the tolerance, and are passed over (the clutter of
  // a room makes most pairs such).
  std::vector<double> reach(n, 0.0);
  for (int a = 0; a < n; ++a) {
    for (int k = 0; k < 4; ++k) {
      const double r = (gap_centre[a][k] - squares[a].centre).norm();
      reach[a] = std::isfinite(r) ? std::max(reach[a], r) : std::numeric_limits<double>::infinity();
    }
  }
  std::vector<std::array<Link, 4>> best(n);
  for (int a = 0; a < n; ++a) {
    for (int k = 0; k < 4; ++k) {
      if (!gap_centre[a][k].allFinite()) continue;
      double nearest = std::numeric_limits<double>::infinity();
      for (int b = 0; b < n; ++b) {
        const double ratio = squares[b].side_px / squares[a].side_px;
        if (b == a || ratio > kMaxSideRatio || ratio < 1.0 / kMaxSideRatio) continue;
        const double tol = max_fraction * 0.5 * (squares[a].side_px + squares[b].side_px);
        // 1 px of margin for rounding: the test only skips pairs that cannot link.
        if ((squares[b].centre - squares[a].centre).norm() > reach[a] + reach[b] + tol + 1.0) {
          continue;
        }
        for (int m = 0; m < 4; ++m) {
          const double dist = (gap_centre[b][m] - gap_centre[a][k]).norm();
          const double half_gap_ratio = half_gap[b][m] / half_gap[a][k];
          if (dist <= tol && dist < nearest && half_gap_ratio <= kMaxSideRatio &&
              half_gap_ratio >= 1.0 / kMaxSideRatio) {
            nearest = dist;
            best[a][k] = Link{b, m};
          }
        }
      }
    }
  }
  std::vector<std::array<Link, 4>> links(n);
  for (int a = 0; a < n; ++a) {
    for (int k = 0; k < 4; ++k) {
      const Link& l = best[a][k];
      if (l.square >= 0 && best[l.square][l.side].square == a && best[l.square][l.side].side == k) {
        links[a][k] = l;
      }
    }
  }
  return links;
}

struct GridSquare {
  int square = 0;
  int rotation = 0;  // global direction g (0 +i, 1 +j, 2 -i, 3 -j) is side (rotation + g) % 4
};

// The smallest and largest grid indices (i, j) of a linked group's squares.
struct GroupBounds {
  int i_lo = 1 << 30, i_hi = -(1 << 30), j_lo = 1 << 30, j_hi = -(1 << 30);
};
GroupBounds BoundsOf(const std::map<std::pair<int, int>, GridSquare>& group) {
  GroupBounds b;
  for (const auto& entry : group) {
    b.i_lo = std::min(b.i_lo, entry.first.first);
    b.i_hi = std::max(b.i_hi, entry.first.first);
    b.j_lo = std::min(b.j_lo, entry.first.second);
    b.j_hi = std::max(b.j_hi, entry.first.second);
  }
  return b;
}

// Connected groups of linked squares with integer grid coordinates (i right, j down,
// right-handed in the image), spread breadth-first; a link that would put a second square on
// a grid point is not followed.
std::vector<std::map<std::pair<int, int>, GridSquare>> GridGroups(
    const std::vector<std::array<Link, 4>>& links) {
  constexpr std::array<int, 4> kDi = {1, 0, -1, 0};
  constexpr std::array<int, 4> kDj = {0, 1, 0, -1};
  const int n = static_cast<int>(links.size());
  std::vector<bool> placed(n, false);
  std::vector<std::map<std::pair<int, int>, GridSquare>> groups;
  for (int seed = 0; seed < n; ++seed) {
    if (placed[seed]) continue;
    placed[seed] = true;
    std::map<std::pair<int, int>, GridSquare> at = {{{0, 0}, GridSquare{seed, 0}}};
    std::deque<std::pair<int, int>> queue = {{0, 0}};
    while (!queue.empty()) {
      const std::pair<int, int> point = queue.front();
      queue.pop_front();
      const GridSquare here = at.at(point);
      for (int g = 0; g < 4; ++g) {
        const Link& link = links[here.square][(here.rotation + g) % 4];
        if (link.square < 0 || placed[link.square]) continue;
        const std::pair<int, int> next = {point.first + kDi[g], point.second + kDj[g]};
        if (at.count(next) != 0) continue;
        placed[link.square] = true;
        // Its side facing back points along global direction g + 2.
        at[next] = GridSquare{link.square, (link.side - g - 2 + 8) % 4};
        queue.push_back(next);
      }
    }
    groups.push_back(std::move(at));
  }
  return groups;
}

// ---- 3. Windows ---------------------------------------------------------------------------

// A complete w x h placement of squares: square (i, j) at squares[j * w + i]. Its corner
// lattice is 2w x 2h points; point (x, y) is corner (x % 2, y % 2) of square (x / 2, y / 2).
struct Window {
  int w = 0, h = 0;
  std::vector<GridSquare> squares;
  std::vector<const Square*> geometry;

  const Square& At(int i, int j) const { return *geometry[j * w + i]; }
  // Lattice point (x, y): the square's top-left, top-right, bottom-right, bottom-left corner
  // in grid directions are its corners rotation + 3, + 0, + 1, + 2.
  const Eigen::Vector2d& Corner(int x, int y) const {
    static constexpr int kCornerOf[2][2] = {{3, 2}, {0, 1}};  // [x % 2][y % 2]
    const int i = x / 2, j = y / 2;
    return At(i, j).corners[(squares[j * w + i].rotation + kCornerOf[x % 2][y % 2]) % 4];
  }
};

// Calls fn(p0, p1, p2, p3) for the corners of every two neighbouring squares along each row
// and column of the corner lattice, in order along the line; stops at the first false.
template <typename Fn>
bool ForEachGapLine(const Window& win, Fn&& fn) {
  for (int y = 0; y < 2 * win.h; ++y) {
    for (int x = 1; x + 2 < 2 * win.w; x += 2) {
      if (!fn(win.Corner(x - 1, y), win.Corner(x, y), win.Corner(x + 1, y), win.Corner(x + 2, y))) {
        return false;
      }
    }
  }
  for (int x = 0; x < 2 * win.w; ++x) {
    for (int y = 1; y + 2 < 2 * win.h; y += 2) {
      if (!fn(win.Corner(x, y - 1), win.Corner(x, y), win.Corner(x, y + 1), win.Corner(x, y + 2))) {
        return false;
      }
    }
  }
  return true;
}

// Along every row and column of the corner lattice, each gap against the squares on either
// side of it: the corners of two neighbouring squares lie at 0, 1, 1 + r and 2 + r sides
// along the line (r the gap over the side), so the gap's image vector is r times the mean of
// the two squares' side vectors there. That holds exactly for any quadratic image of the
// line: perspective and a lens's bending over one pitch drop out (a fisheye bends the board's
// corner squares by over half a side against a quadratic through 3 x 3 squares), while a
// square that is not the grid's is off by a good part of a side. Each within max(1 px,
// fraction x the two squares' mean side). The window's corners must have the squares'
// dilation taken out (below): it changes r by the same amount along every line, 3-4 px of a
// 15 px square's gap under blur 1.5 and a gamma, as much as the tolerance.
//
// In a window with lines both ways (at least 2 x 2 squares) only the residual's component
// along its line is held: a corner's shift across a row is a shift along the column through
// it, which that column's gaps hold (every corner lies on one of each; a square moved,
// turned, scaled or sheared moves its corners along one or the other). The component across
// carries what the side fits get wrong: a side's angle error moves its two corners across
// the line by the lever of half a side, and the fits make a small blurred square more
// sheared than it is (its acute corners out along their bisectors, its obtuse corners in,
// 0.2-0.4 px on 13 px squares turned 50 degrees under the hard effects), which turns every
// side of a row alike: on average up to 0.8-1 px across the lines against 0.1-0.3 px along
// them (docs/detectors.md, "The four sheared misses"). A pair of squares (PairConsistent)
// has lines one way only and keeps the whole residual.
bool LocallyConsistent(const Window& win, double gap_ratio, double fraction) {
  const bool lines_both_ways = win.w >= 2 && win.h >= 2;
  return ForEachGapLine(win, [&](const Eigen::Vector2d& p0, const Eigen::Vector2d& p1,
                                 const Eigen::Vector2d& p2, const Eigen::Vector2d& p3) {
    const double side = 0.5 * ((p1 - p0).norm() + (p3 - p2).norm());
    const Eigen::Vector2d r = (p2 - p1) - 0.5 * gap_ratio * ((p1 - p0) + (p3 - p2));
    const double residual = lines_both_ways ? std::abs(r.dot((p3 - p0).normalized())) : r.norm();
    return residual <= std::max(1.0, fraction * side);
  });
}

// Corners located on edges carry one bias that the geometry cannot show square by square: a
// gamma applied after the optics' blur (and ink spread) moves every dark-to-light edge out or
// in by the same amount, so every square grows or shrinks about its centre while the pitch
// stays (measured on renders with gamma 1.4 and blur 1: 0.3 px RMS). The print's gap over
// its side, r, measures it: seen as q (the gaps' length over the squares' along every line
// of the lattice), the squares have grown by d sides at each edge with q = (r - 2d) / (1 + 2d).
// Returns d / (1 + 2d): the fraction of a seen side by which each corner lies outwards along
// both sides of its square; *d_px: d in pixels of the window's mean side.
double DilationFraction(const Window& win, double gap_ratio, double* d_px) {
  double gaps = 0.0, sides = 0.0;
  int lines = 0;
  ForEachGapLine(win, [&](const Eigen::Vector2d& p0, const Eigen::Vector2d& p1,
                          const Eigen::Vector2d& p2, const Eigen::Vector2d& p3) {
    gaps += (p2 - p1).norm();
    sides += 0.5 * ((p1 - p0).norm() + (p3 - p2).norm());
    ++lines;
    return true;
  });
  const double q = gaps / sides;
  const double d = (gap_ratio - q) / (2.0 * (1.0 + q));
  *d_px = d * sides / lines;
  return d / (1.0 + 2.0 * d);
}

// The largest dilation taken out, pixels: the edge shift of a gamma after the optics' blur is
// about a third of the blur's sigma (0.5-0.9 px at blur 1.5 and gamma 0.6 or 1.6, measured on
// the hard renders of detectors_eval); a print whose gap over its side differs from the
// board's seems dilated by a share of every side (a gap of 0.8 side for 1.0: 8% of it), which
// this bounds on squares over 25 px.
constexpr double kMaxDilationPx = 2.0;

// Square `s` with its dilation taken out: each corner moved inwards along both sides of the
// square by `fraction` of its mean side vectors (DilationFraction); nullopt when the corners
// give no homography.
std::optional<Square> Undilated(const Square& s, double fraction) {
  const std::array<Eigen::Vector2d, 4>& c = s.corners;
  const Eigen::Vector2d across = 0.5 * (c[1] - c[0] + c[2] - c[3]);
  const Eigen::Vector2d down = 0.5 * (c[3] - c[0] + c[2] - c[1]);
  return MakeSquare({c[0] + fraction * (across + down), c[1] + fraction * (down - across),
                     c[2] - fraction * (across + down), c[3] + fraction * (across - down)});
}

// The squares of `win` with the dilation `fraction` taken out (Undilated), and the window on
// them; nullopt when a square gives no homography.
struct UndilatedWindow {
  std::vector<Square> squares;
  Window win;  // on `squares`: moved (the vector keeps its storage), never copied

  UndilatedWindow() = default;
  UndilatedWindow(UndilatedWindow&&) = default;
  UndilatedWindow(const UndilatedWindow&) = delete;
};
std::optional<UndilatedWindow> UndilatedWindowOf(const Window& win, double fraction) {
  UndilatedWindow out;
  out.squares.reserve(win.geometry.size());
  for (const Square* s : win.geometry) {
    std::optional<Square> u = Undilated(*s, fraction);
    if (!u) return std::nullopt;
    out.squares.push_back(*u);
  }
  out.win.w = win.w;
  out.win.h = win.h;
  out.win.squares = win.squares;
  for (const Square& s : out.squares) out.win.geometry.push_back(&s);
  return std::optional<UndilatedWindow>(std::move(out));
}

// Two neighbouring squares at grid points a and b (4-neighbours) as a window of their own,
// their dilation `dilation` taken out (DilationFraction), LocallyConsistent.
bool PairConsistent(const std::vector<Square>& squares, const GridSquare& a,
                    std::pair<int, int> at_a, const GridSquare& b, std::pair<int, int> at_b,
                    double gap_ratio, double fraction, double dilation) {
  const bool b_first = at_b < at_a;
  Window pair;
  pair.w = at_a.first == at_b.first ? 1 : 2;
  pair.h = 3 - pair.w;
  pair.squares = b_first ? std::vector<GridSquare>{b, a} : std::vector<GridSquare>{a, b};
  for (const GridSquare& gs : pair.squares) pair.geometry.push_back(&squares[gs.square]);
  const std::optional<UndilatedWindow> undilated = UndilatedWindowOf(pair, dilation);
  return undilated && LocallyConsistent(undilated->win, gap_ratio, fraction);
}

// The mean grey at uv and at four points spread_px away along the image axes (noise
// averaged, inside a gap or square of twice spread_px); nullopt when a point leaves the image.
std::optional<double> MeanGrey(const ImageView8& image, const Eigen::Vector2d& uv,
                               double spread_px) {
  double sum = 0.0;
  for (const auto& [dx, dy] :
       {std::pair{0.0, 0.0}, {1.0, 0.0}, {-1.0, 0.0}, {0.0, 1.0}, {0.0, -1.0}}) {
    const Eigen::Vector2d p = uv + spread_px * Eigen::Vector2d(dx, dy);
    if (!InsideForBilinearGrey(image, p)) return std::nullopt;
    sum += BilinearGrey(image, p.x(), p.y());
  }
  return sum / 5.0;
}

// The light level of the gaps where the window lies: a plane through the grey levels of the
// gaps' centres (`points`: position, grey), which takes out the light's gradient across the
// board (a 4:1 gradient leaves the dim end's gaps at half the median gap's grey); the mean
// grey where the points give no plane (a single row). `points` not empty.
struct LightPlane {
  Eigen::Vector3d coefficients = Eigen::Vector3d::Zero();  // grey = c0 + c1 du + c2 dv
  Eigen::Vector2d origin = Eigen::Vector2d::Zero();        // the points' mean position

  double At(const Eigen::Vector2d& uv) const {
    const Eigen::Vector2d d = uv - origin;
    return coefficients(0) + coefficients(1) * d.x() + coefficients(2) * d.y();
  }
};
LightPlane FitLightPlane(const std::vector<std::pair<Eigen::Vector2d, double>>& points) {
  LightPlane plane;
  double mean_grey = 0.0;
  for (const auto& point : points) {
    plane.origin += point.first;
    mean_grey += point.second;
  }
  plane.origin /= static_cast<double>(points.size());
  mean_grey /= static_cast<double>(points.size());
  Eigen::Matrix3d normal = Eigen::Matrix3d::Zero();
  Eigen::Vector3d rhs = Eigen::Vector3d::Zero();
  for (const auto& point : points) {
    const Eigen::Vector2d d = point.first - plane.origin;
    const Eigen::Vector3d row(1.0, d.x(), d.y());
    normal += row * row.transpose();
    rhs += point.second * row;
  }
  const Eigen::FullPivLU<Eigen::Matrix3d> lu(normal);
  if (lu.rank() == 3) {
    plane.coefficients = lu.solve(rhs);
  } else {
    plane.coefficients(0) = mean_grey;
  }
  return plane;
}

// The paint of the window: the board's contrast (the median light sample minus the median
// square) at least min_contrast, and every gap between neighbouring squares and every
// crossing of gaps lighter than the mean of the squares around it by at least min_contrast
// and half the local contrast: the gaps' light level there (FitLightPlane) minus those
// squares. A chessboard prints a black square at every crossing; an AprilGrid, a corner
// square.
bool PaintAgrees(const ImageView8& image, const Window& win, int min_contrast) {
  std::vector<double> dark(win.w * win.h);
  for (int j = 0; j < win.h; ++j) {
    for (int i = 0; i < win.w; ++i) {
      const Square& s = win.At(i, j);
      const std::optional<double> v = MeanGrey(image, s.centre, 0.2 * s.side_px);
      if (!v) return false;
      dark[j * win.w + i] = *v;
    }
  }
  // Light points: the centre of the inner corners between the squares (i, j) .. (i + di,
  // j + dj), with the squares around it.
  struct Light {
    Eigen::Vector2d centre;
    double value;
    double around;
  };
  std::vector<Light> light;
  std::vector<std::pair<Eigen::Vector2d, double>> gaps;
  for (int j = 0; j < win.h; ++j) {
    for (int i = 0; i < win.w; ++i) {
      for (const auto& [di, dj] : {std::pair{1, 0}, {0, 1}, {1, 1}}) {
        if (i + di >= win.w || j + dj >= win.h) continue;
        Eigen::Vector2d centre = Eigen::Vector2d::Zero();
        double around = 0.0, side = 0.0;
        int n = 0;
        for (int y = 2 * j + dj; y <= 2 * j + 1 + dj; ++y) {
          for (int x = 2 * i + di; x <= 2 * i + 1 + di; ++x) {
            centre += win.Corner(x, y);
            ++n;
          }
        }
        centre /= n;
        for (int jj = j; jj <= j + dj; ++jj) {
          for (int ii = i; ii <= i + di; ++ii) {
            around += dark[jj * win.w + ii];
            side += win.At(ii, jj).side_px;
          }
        }
        const int squares_around = (di + 1) * (dj + 1);
        const std::optional<double> v = MeanGrey(image, centre, 0.1 * side / squares_around);
        if (!v) return false;
        light.push_back({centre, *v, around / squares_around});
        if (di + dj == 1) gaps.emplace_back(centre, *v);
      }
    }
  }
  std::vector<double> light_values;
  for (const Light& l : light) light_values.push_back(l.value);
  const auto median = [](std::vector<double> v) {
    std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
    return v[v.size() / 2];
  };
  const double contrast = median(light_values) - median(dark);
  if (!(contrast >= min_contrast)) return false;
  const LightPlane plane = FitLightPlane(gaps);
  return std::all_of(light.begin(), light.end(), [&](const Light& l) {
    return l.value - l.around >=
           std::max<double>(min_contrast, 0.5 * (plane.At(l.centre) - l.around));
  });
}

// A verified window in one of its orientations: feature id and image position.
struct Hypothesis {
  std::vector<std::pair<int, Eigen::Vector2d>> id_uv;
  double x_axis_u = 0.0;  // image u component of the board's +x direction at the centre
};

// The rotations of a verified window (its squares' dilation taken out) onto the board's
// corner lattice (C, R), the most upright (header); nullopt when none fits cols x rows.
// Rotation k of the lattice point (x, y) of a 2w x 2h lattice: 0: (x, y); 1: (y, 2w-1-x); 2:
// (2w-1-x, 2h-1-y); 3: (2h-1-y, x).
std::optional<Hypothesis> Orient(const Window& win, int cols, int rows) {
  const int ci = std::min((win.w - 1) / 2, win.w - 2), cj = std::min((win.h - 1) / 2, win.h - 2);
  const Eigen::Vector2d step_i = win.At(ci + 1, cj).centre - win.At(ci, cj).centre;
  const Eigen::Vector2d step_j = win.At(ci, cj + 1).centre - win.At(ci, cj).centre;
  const std::array<Eigen::Vector2d, 4> x_axis = {step_i, step_j, -step_i, -step_j};
  std::optional<Hypothesis> best;
  for (int k = 0; k < 4; ++k) {
    const bool swapped = k % 2 == 1;
    if ((swapped ? win.h : win.w) != cols || (swapped ? win.w : win.h) != rows) continue;
    const double u = x_axis[k].normalized().x();
    if (best && u <= best->x_axis_u) continue;
    Hypothesis hyp;
    hyp.x_axis_u = u;
    const int lw = 2 * win.w, lh = 2 * win.h;
    for (int y = 0; y < lh; ++y) {
      for (int x = 0; x < lw; ++x) {
        int c = 0, r = 0;
        switch (k) {
          case 0:
            c = x;
            r = y;
            break;
          case 1:
            c = y;
            r = lw - 1 - x;
            break;
          case 2:
            c = lw - 1 - x;
            r = lh - 1 - y;
            break;
          default:
            c = lh - 1 - y;
            r = x;
            break;
        }
        hyp.id_uv.emplace_back(2 * cols * r + c, win.Corner(x, y));
      }
    }
    best = std::move(hyp);
  }
  return best;
}

// What the search of the groups gave: the verified windows' hypotheses, and the reason of the
// last refusal (kTooFewFeatures when no group held a complete window).
struct Search {
  std::vector<Hypothesis> found;
  std::vector<std::vector<int>> found_squares;  // each hypothesis's squares, sorted
  DetectReason refusal = DetectReason::kTooFewFeatures;
};

void SearchGroup(const ImageView8& image, const std::vector<Square>& squares,
                 const std::map<std::pair<int, int>, GridSquare>& group, const Board& board,
                 const SquareGridOptions& options, int min_contrast, Search* search) {
  const int cols = board.params().cols, rows = board.params().rows;
  if (static_cast<int>(group.size()) < cols * rows) return;
  const double pitch_ratio = 1.0 + board.params().gap_m / board.params().square_m;
  std::vector<std::pair<int, int>> sizes = {{cols, rows}};
  if (cols != rows) sizes.emplace_back(rows, cols);
  const GroupBounds b = BoundsOf(group);
  const int i_lo = b.i_lo, i_hi = b.i_hi, j_lo = b.j_lo, j_hi = b.j_hi;  // lambdas capture them
  for (const std::pair<int, int>& size : sizes) {
    // Plain ints, not structured bindings: the lambda below captures them (clang 14 refuses
    // to capture a binding, and the fuzz build uses clang).
    const int w = size.first, h = size.second;
    for (int wj = j_lo; wj + h - 1 <= j_hi; ++wj) {
      for (int wi = i_lo; wi + w - 1 <= i_hi; ++wi) {
        Window win;
        win.w = w;
        win.h = h;
        for (int j = wj; j < wj + h; ++j) {
          for (int i = wi; i < wi + w; ++i) {
            const auto it = group.find({i, j});
            if (it == group.end()) break;
            win.squares.push_back(it->second);
            win.geometry.push_back(&squares[it->second.square]);
          }
        }
        if (static_cast<int>(win.squares.size()) != w * h) continue;
        double dilation_px = 0.0;
        const double dilation = DilationFraction(win, pitch_ratio - 1.0, &dilation_px);
        const std::optional<UndilatedWindow> undilated = std::abs(dilation_px) <= kMaxDilationPx
                                                             ? UndilatedWindowOf(win, dilation)
                                                             : std::nullopt;
        if (!undilated ||
            !LocallyConsistent(undilated->win, pitch_ratio - 1.0,
                               options.max_residual_side_fraction) ||
            !PaintAgrees(image, win, min_contrast)) {
          search->refusal = DetectReason::kVerificationFailed;
          continue;
        }
        // The grid goes on: a square linked next to the window along one of its sides, in
        // the gap geometry of the window's square beside it (a dark shadow or edge that
        // touches a square links as a neighbour of another size, no gap away), with sides
        // as straight as a printed square's (kMaxEdgeRmsRatio).
        double window_edge_rms_px = 0.0;
        for (const Square* s : win.geometry) {
          window_edge_rms_px = std::max(window_edge_rms_px, s->edge_rms_px);
        }
        const bool continues = std::any_of(group.begin(), group.end(), [&](const auto& entry) {
          if (squares[entry.second.square].edge_rms_px > kMaxEdgeRmsRatio * window_edge_rms_px) {
            return false;
          }
          const auto [i, j] = entry.first;
          const bool in_i = i >= wi && i < wi + w, in_j = j >= wj && j < wj + h;
          std::pair<int, int> inside = {i, j};
          if (in_i && j == wj - 1)
            inside.second = wj;
          else if (in_i && j == wj + h)
            inside.second = wj + h - 1;
          else if (in_j && i == wi - 1)
            inside.first = wi;
          else if (in_j && i == wi + w)
            inside.first = wi + w - 1;
          else
            return false;
          return PairConsistent(squares, group.at(inside), inside, entry.second, entry.first,
                                pitch_ratio - 1.0, options.max_residual_side_fraction, dilation);
        });
        if (continues) {
          search->refusal = DetectReason::kWrongBoard;
          continue;
        }
        std::optional<Hypothesis> hyp = Orient(undilated->win, cols, rows);
        if (!hyp) continue;
        std::vector<int> ids;
        for (const GridSquare& gs : win.squares) ids.push_back(gs.square);
        std::sort(ids.begin(), ids.end());
        search->found.push_back(*std::move(hyp));
        search->found_squares.push_back(std::move(ids));
      }
    }
  }
}

// ---- 4. Squares the binarisation lost -------------------------------------------------------

// A window may lack this fraction of its squares (at least one) for them to be looked for:
// the rest of the grid, linked, places each of them to a fraction of a side.
constexpr double kMaxMissingFraction = 0.125;

// Where a square is looked for (method, step 4): its centre predicted by its linked
// neighbours, their mean side, their dark level and the light level of the gaps between
// them and it.
struct Prediction {
  Eigen::Vector2d centre = Eigen::Vector2d::Zero();
  double side_px = 0.0;
  double dark = 0.0;
  double light = 0.0;
};

// The square at grid point `point` of `group`, predicted by its 4-neighbours in the group:
// each carries its homography one pitch over (a neighbour on each side averages a lens's
// bending out; near a fisheye's rim one neighbour alone can miss by a third of a side).
// nullopt with fewer than two neighbours or a sample off the image.
std::optional<Prediction> PredictSquare(const ImageView8& image, const std::vector<Square>& squares,
                                        const std::map<std::pair<int, int>, GridSquare>& group,
                                        std::pair<int, int> point, double gap_ratio) {
  constexpr std::array<int, 4> kDi = {1, 0, -1, 0};
  constexpr std::array<int, 4> kDj = {0, 1, 0, -1};
  Prediction p;
  int n = 0;
  for (int g = 0; g < 4; ++g) {
    const auto it = group.find({point.first + kDi[g], point.second + kDj[g]});
    if (it == group.end()) continue;
    const Square& s = squares[it->second.square];
    // The neighbour's side that faces the missing square points along global direction g + 2.
    const std::array<double, 2>& out = kSideDirection[(it->second.rotation + g + 2) % 4];
    const double pitch = 1.0 + gap_ratio, half_gap = 0.5 + 0.5 * gap_ratio;
    const Eigen::Vector2d centre =
        ApplyHomography(s.H, Eigen::Vector2d(0.5 + pitch * out[0], 0.5 + pitch * out[1]));
    const Eigen::Vector2d gap =
        ApplyHomography(s.H, Eigen::Vector2d(0.5 + half_gap * out[0], 0.5 + half_gap * out[1]));
    if (!centre.allFinite() || !gap.allFinite()) return std::nullopt;
    const std::optional<double> light = MeanGrey(image, gap, 0.1 * s.side_px);
    const std::optional<double> dark = MeanGrey(image, s.centre, 0.2 * s.side_px);
    if (!light || !dark) return std::nullopt;
    p.centre += centre;
    p.side_px += s.side_px;
    p.dark += *dark;
    p.light += *light;
    ++n;
  }
  if (n < 2) return std::nullopt;
  p.centre /= n;
  p.side_px /= n;
  p.dark /= n;
  p.light /= n;
  return p;
}

// The dark square at a prediction, found in a window around it with a threshold of its own:
// halfway between its neighbours' dark level and the gaps' light level. A lens's dark rim
// or a shadow next to a square lowers the local-contrast threshold there, so that the
// square's edge falls on its light side and its quad loses its corners. The window reaches
// half a gap beyond the square at any turn; the quad nearest the predicted centre, within
// half a side (a neighbour is a pitch away), refined as the others (its corners on its own
// edges) and of a side within kMaxSideRatio of the prediction's. nullopt when there is none.
std::optional<Square> FindPredictedSquare(const ImageView8& image, const Prediction& p,
                                          double gap_ratio, int min_contrast, int min_side_px) {
  if (!(p.light - p.dark >= min_contrast)) return std::nullopt;
  const double threshold = 0.5 * (p.dark + p.light);
  const double reach = std::sqrt(0.5) * (1.0 + gap_ratio) * p.side_px;
  const int x0 = std::max(0, static_cast<int>(std::floor(p.centre.x() - reach)));
  const int y0 = std::max(0, static_cast<int>(std::floor(p.centre.y() - reach)));
  const int x1 = std::min(image.width - 1, static_cast<int>(std::ceil(p.centre.x() + reach)));
  const int y1 = std::min(image.height - 1, static_cast<int>(std::ceil(p.centre.y() + reach)));
  if (x1 - x0 < min_side_px || y1 - y0 < min_side_px) return std::nullopt;
  Image8 window(x1 - x0 + 1, y1 - y0 + 1);
  for (int y = y0; y <= y1; ++y) {
    for (int x = x0; x <= x1; ++x) window.at(x - x0, y - y0) = image.At(x, y) < threshold;
  }
  const Eigen::Vector2d origin(x0, y0);
  std::optional<Square> best;
  double nearest = 0.5 * p.side_px;
  const ComponentLabels labels = LabelComponents(window.view(), /*label_image=*/false);
  for (const Quad& quad : FindQuads(labels, SquareQuadOptions(min_side_px))) {
    std::optional<std::array<Eigen::Vector2d, 4>> corners = quad.corners_px;
    for (Eigen::Vector2d& c : *corners) c += origin;
    double edge_rms_px = 0.0;
    for (int pass = 0; pass < 2 && corners; ++pass) {
      corners = RefineCorners(image, *corners, gap_ratio, &edge_rms_px);
    }
    if (!corners) continue;
    std::optional<Square> s = MakeSquare(*corners);
    if (!s) continue;
    s->edge_rms_px = edge_rms_px;
    const double ratio = s->side_px / p.side_px;
    const double dist = (s->centre - p.centre).norm();
    if (ratio > kMaxSideRatio || ratio < 1.0 / kMaxSideRatio || dist > nearest) continue;
    nearest = dist;
    best = s;
  }
  return best;
}

// The squares missing from windows of a group that lack at most kMaxMissingFraction of
// their squares, each found at its prediction (FindPredictedSquare); empty when none is.
std::vector<Square> RecoverSquares(const ImageView8& image, const std::vector<Square>& squares,
                                   const std::map<std::pair<int, int>, GridSquare>& group,
                                   const Board& board, int min_contrast, int min_side_px) {
  const int cols = board.params().cols, rows = board.params().rows;
  const double gap_ratio = board.params().gap_m / board.params().square_m;
  const int max_missing = std::max(1, static_cast<int>(kMaxMissingFraction * cols * rows));
  std::vector<Square> found;
  if (static_cast<int>(group.size()) < cols * rows - max_missing) return found;
  const GroupBounds b = BoundsOf(group);
  const int i_lo = b.i_lo, i_hi = b.i_hi, j_lo = b.j_lo, j_hi = b.j_hi;  // lambdas capture them
  std::set<std::pair<int, int>> tried;
  for (const auto& [w, h] : {std::pair{cols, rows}, std::pair{rows, cols}}) {
    for (int wj = j_lo; wj + h - 1 <= j_hi; ++wj) {
      for (int wi = i_lo; wi + w - 1 <= i_hi; ++wi) {
        std::vector<std::pair<int, int>> missing;
        for (int j = wj; j < wj + h; ++j) {
          for (int i = wi; i < wi + w; ++i) {
            if (group.count({i, j}) == 0) missing.emplace_back(i, j);
          }
        }
        if (missing.empty() || static_cast<int>(missing.size()) > max_missing) continue;
        for (const std::pair<int, int>& point : missing) {
          if (!tried.insert(point).second) continue;
          const std::optional<Prediction> p =
              PredictSquare(image, squares, group, point, gap_ratio);
          if (!p) continue;
          if (std::optional<Square> s =
                  FindPredictedSquare(image, *p, gap_ratio, min_contrast, min_side_px)) {
            found.push_back(*s);
          }
        }
      }
    }
  }
  return found;
}

// The verified windows of every linked group of `squares` (steps 2 and 3); the groups in
// *groups.
Search SearchSquares(const ImageView8& image, const std::vector<Square>& squares,
                     const Board& board, const SquareGridOptions& options, int min_contrast,
                     std::vector<std::map<std::pair<int, int>, GridSquare>>* groups) {
  const double gap_ratio = board.params().gap_m / board.params().square_m;
  *groups = GridGroups(LinkSquares(squares, gap_ratio, options.max_link_side_fraction));
  Search search;
  for (const auto& group : *groups) {
    SearchGroup(image, squares, group, board, options, min_contrast, &search);
  }
  return search;
}

}  // namespace

std::string_view SquareGridOptions::Validate() const {
  if (!(min_contrast >= 4 && min_contrast <= 200)) return "min_contrast";
  if (!(noise_contrast_factor >= 0.0 && noise_contrast_factor <= 10.0)) {
    return "noise_contrast_factor";
  }
  if (!(min_square_side_px >= 6 && min_square_side_px <= 1000)) return "min_square_side_px";
  if (!(max_link_side_fraction > 0.0 && max_link_side_fraction <= 0.5)) {
    return "max_link_side_fraction";
  }
  if (!(max_residual_side_fraction > 0.0 && max_residual_side_fraction <= 0.5)) {
    return "max_residual_side_fraction";
  }
  return {};
}

Detection DetectSquareGrid(const ImageView8& image, const Board& board,
                           const SquareGridOptions& options) {
  Detection result;
  result.reason =
      CheckDetectorInput(image, board, BoardType::kSquareGrid, options.Validate().empty());
  if (result.reason != DetectReason::kNone) return result;
  const BoardParams& params = board.params();
  const double gap_ratio = params.gap_m / params.square_m;

  const int min_contrast = std::max(
      options.min_contrast,
      static_cast<int>(std::ceil(options.noise_contrast_factor * EstimateNoiseSigma(image))));
  int max_contrast = 0;
  const Image8 dark = BinariseDark(image, min_contrast, &max_contrast);
  if (max_contrast < min_contrast) {
    result.reason = DetectReason::kLowContrast;
    return result;
  }
  std::vector<Square> squares = FindSquares(image, dark, gap_ratio, options.min_square_side_px);
  if (squares.empty()) {
    result.reason = DetectReason::kNoCandidates;
    return result;
  }
  std::vector<std::map<std::pair<int, int>, GridSquare>> groups;
  Search search = SearchSquares(image, squares, board, options, min_contrast, &groups);
  if (search.found.empty()) {
    // Step 4: the squares that the grid places where the binarisation lost them, then every
    // check again with them among the others.
    std::vector<Square> recovered;
    for (const auto& group : groups) {
      for (const Square& s :
           RecoverSquares(image, squares, group, board, min_contrast, options.min_square_side_px)) {
        recovered.push_back(s);
      }
    }
    if (!recovered.empty()) {
      squares.insert(squares.end(), recovered.begin(), recovered.end());
      Search again = SearchSquares(image, squares, board, options, min_contrast, &groups);
      if (!again.found.empty()) search = std::move(again);
    }
  }
  if (search.found.empty()) {
    result.reason = search.refusal;
    return result;
  }
  for (const std::vector<int>& other : search.found_squares) {
    if (other != search.found_squares.front()) {
      result.reason = DetectReason::kAmbiguous;
      return result;
    }
  }
  result.features.resize(search.found.front().id_uv.size());
  for (const auto& [id, uv] : search.found.front().id_uv) {
    DetectedFeature& f = result.features[id];
    f.id = id;
    f.uv_px = uv;
    f.p_board = board.features()[id].p_board;
    f.marker = board.features()[id].marker;
  }
  result.found = true;
  result.reason = DetectReason::kNone;
  return result;
}

}  // namespace linecal
